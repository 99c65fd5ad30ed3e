//! `roomlight camera`: the camera agent's model and camera from the files of a calibrated room
//! or a survey, served until cancelled, its rounds summarised on stdout (or one status line per
//! round, `status`). The camera is the
//! simulator's (over gRPC) or a real one (roomlight-camera's `HwCamera`: a folder, a command,
//! a V4L2 device) sampled at the charts.

use super::files::{ChartsFile, ModelFile, load_model, read_json};
use super::lights::{LightsSpec, ManualLights};
use super::survey::{SurveyRoom, survey_model};
use crate::rendered::RenderedCamera;
use anyhow::{Context, Result, bail};
use roomlight_agent::AgentError;
use roomlight_agent::camera::{self, CameraConfig, RoomModel};
use roomlight_agent::discovery::{self, MdnsConfig};
use roomlight_agent::remote::RemoteCamera;
use roomlight_calib::image_io::LinearImage;
use roomlight_camera::{Charts, HwCamera};
use roomlight_core::LinearRgb;
use std::io::Write;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::pin::Pin;
use std::sync::Arc;
use std::time::Duration;
use tokio_util::sync::CancellationToken;

/// Where the camera agent's model comes from.
#[derive(Debug, Clone)]
pub enum CameraSource {
    /// A calibrated model; with `charts` the camera is a rendered room's, sampled at them,
    /// without it the synthetic room's patches.
    Model {
        model: PathBuf,
        charts: Option<PathBuf>,
    },
    /// Calibration over the wire on a rendered room: each projector is calibrated through its
    /// node agent as it joins; `preset` is the LED preset reproduced (default: the first);
    /// `dark_weight` weighs the light on the target in the luminaires' objective
    /// (`camera::Survey::new`; 0: the charts alone).
    Survey {
        survey: PathBuf,
        preset: Option<String>,
        dark_weight: f64,
    },
}

/// What the camera agent photographs the room with.
#[derive(Debug, Clone)]
pub enum CameraHardware {
    /// The `roomlight sim` process at this endpoint serves the camera.
    Sim(String),
    /// A real camera with its radiometry. `lights`: how the survey switches the LEDs off and
    /// on to measure the room's black and target (a rendered room's own, `roomlight sim
    /// --grab`, or a person asked through files); calibration over the wire needs it.
    Real {
        camera: Box<roomlight_camera::CameraConfig>,
        lights: Option<LightsSpec>,
    },
}

/// A camera agent.
#[derive(Debug, Clone)]
pub struct CameraProcess {
    pub agent: CameraConfig,
    pub hardware: CameraHardware,
    pub source: CameraSource,
    /// Where node agents attach.
    pub listen: String,
    /// Advertise the agent over mDNS.
    pub advertise: Option<MdnsConfig>,
    /// TLS (plaintext when `None`: loopback, or `insecure` in its config).
    pub tls: Option<roomlight_agent::tls::ServerTls>,
    /// The installer's web console, if served.
    pub console: Option<ConsoleProcess>,
    /// What it prints about the rounds on stdout.
    pub status_lines: super::StatusLines,
}

/// Where and for whom the installer's console is served.
#[derive(Clone)]
pub struct ConsoleProcess {
    /// Its address (`127.0.0.1:8080`; port 0: any free port, printed).
    pub listen: String,
    /// The token that logs in.
    pub token: String,
}

impl std::fmt::Debug for ConsoleProcess {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ConsoleProcess")
            .field("listen", &self.listen)
            .field("token", &"<secret>")
            .finish()
    }
}

/// The camera agent's camera: the synthetic room's patches, a rendered room's images sampled
/// at the charts, or a real camera's.
pub(super) enum AnyCamera {
    Synthetic(RemoteCamera),
    Rendered(RenderedCamera),
    Real(HwCamera),
}

impl roomlight_agent::hardware::Camera for AnyCamera {
    fn capture_image(&mut self) -> impl Future<Output = Result<LinearImage, AgentError>> + Send {
        let capture: Pin<Box<dyn Future<Output = _> + Send + '_>> = match self {
            Self::Synthetic(c) => Box::pin(c.capture_image()),
            Self::Rendered(c) => Box::pin(c.capture_image()),
            Self::Real(c) => Box::pin(c.capture_image()),
        };
        capture
    }

    fn capture(&mut self) -> impl Future<Output = Result<Vec<LinearRgb>, AgentError>> + Send {
        let capture: Pin<Box<dyn Future<Output = _> + Send + '_>> = match self {
            Self::Synthetic(c) => Box::pin(c.capture()),
            Self::Rendered(c) => Box::pin(c.capture()),
            Self::Real(c) => Box::pin(c.capture()),
        };
        capture
    }

    fn name(&self) -> &str {
        match self {
            Self::Synthetic(c) => c.name(),
            Self::Rendered(c) => c.name(),
            Self::Real(c) => c.name(),
        }
    }

    fn capture_timeout(&self) -> Duration {
        match self {
            Self::Synthetic(c) => c.capture_timeout(),
            Self::Rendered(c) => c.capture_timeout(),
            Self::Real(c) => c.capture_timeout(),
        }
    }

    fn limits(&self) -> roomlight_calib::rig::CameraLimits {
        match self {
            Self::Synthetic(c) => c.limits(),
            Self::Rendered(c) => c.limits(),
            Self::Real(c) => c.limits(),
        }
    }
}

/// Opens a real camera. A config the camera can never satisfy is an error naming it; a camera
/// that cannot be opened yet (not plugged in, powered off, busy) is tried again with backoff,
/// 1 s doubling to 30 s, with a log line each time: a camera agent started before its camera
/// waits for it rather than exit (the caller stops waiting when the process is stopped).
async fn open_real(config: &roomlight_camera::CameraConfig) -> Result<HwCamera> {
    config
        .validate()
        .with_context(|| format!("the camera {}", config.spec))?;
    let mut wait = Duration::from_secs(1);
    loop {
        match HwCamera::open(config) {
            Ok(camera) => return Ok(camera),
            Err(e) => {
                tracing::warn!(camera = %config.spec, error = %e, retry_in = ?wait, "camera unreachable at start");
                tokio::time::sleep(wait).await;
                wait = (wait * 2).min(Duration::from_secs(30));
            }
        }
    }
}

async fn connect_rendered(hardware: &str) -> Result<crate::rendered::Client> {
    crate::rendered::connect(hardware.to_string())
        .await
        .with_context(|| format!("connecting to the rendered room at {hardware}"))
}

/// The model and camera of a calibrated room.
async fn from_model(
    model_path: &Path,
    charts: Option<&Path>,
    hardware: &CameraHardware,
) -> Result<(RoomModel, AnyCamera)> {
    let model = load_model(model_path)?;
    let camera = match (charts, hardware) {
        (Some(path), hardware) => {
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
            match hardware {
                CameraHardware::Sim(endpoint) => AnyCamera::Rendered(RenderedCamera::new(
                    connect_rendered(endpoint).await?,
                    charts.corners,
                    charts.patches,
                    charts.sample,
                )),
                CameraHardware::Real { camera, .. } => {
                    AnyCamera::Real(open_real(camera).await?.with_charts(Charts {
                        corners: Arc::new(charts.corners),
                        patches: Arc::new(charts.patches),
                        sample: charts.sample,
                    }))
                }
            }
        }
        (None, CameraHardware::Sim(endpoint)) => AnyCamera::Synthetic(
            RemoteCamera::connect(endpoint.clone())
                .await
                .with_context(|| format!("connecting to the camera at {endpoint}"))?,
        ),
        (None, CameraHardware::Real { camera, .. }) => bail!(
            "{}: a real camera ({}) needs the charts its patches are sampled at",
            model_path.display(),
            camera.spec
        ),
    };
    let model = RoomModel {
        problem: model.problem,
        owners: model.owners,
        start: model.start,
        hot: Default::default(),
        survey: None,
    };
    Ok((model, camera))
}

async fn model_and_camera(
    process: &CameraProcess,
) -> Result<(RoomModel, AnyCamera, camera::Extras)> {
    match &process.source {
        CameraSource::Model { model, charts } => {
            let (model, camera) = from_model(model, charts.as_deref(), &process.hardware).await?;
            Ok((model, camera, camera::Extras::default()))
        }
        CameraSource::Survey {
            survey,
            preset,
            dark_weight,
        } => {
            // The model this camera agent wrote before it was restarted, if any.
            let resume: Option<(&Path, ModelFile)> = match &process.agent.model_out {
                Some(out) if out.exists() => Some((out.as_path(), load_model(out)?)),
                _ => None,
            };
            let (room, eye) = match &process.hardware {
                CameraHardware::Sim(endpoint) => (
                    SurveyRoom::Rendered(connect_rendered(endpoint).await?),
                    None,
                ),
                CameraHardware::Real {
                    camera,
                    lights: Some(lights),
                } => {
                    // The camera first: one that cannot be opened yet is waited for (logged,
                    // with backoff) before anything else is asked of the room.
                    let eye = open_real(camera).await?;
                    let room = match lights {
                        LightsSpec::Rendered(endpoint) => {
                            SurveyRoom::Rendered(connect_rendered(endpoint).await?)
                        }
                        LightsSpec::Manual(dir) => SurveyRoom::Physical(ManualLights::new(dir)),
                    };
                    (room, Some(eye))
                }
                CameraHardware::Real { lights: None, .. } => {
                    bail!("calibration over the wire with a real camera needs `lights`")
                }
            };
            survey_model(survey, preset.as_deref(), *dark_weight, resume, room, eye).await
        }
    }
}

/// Serves the console beside the camera agent until `cancel`, printing its address.
fn start_console(
    listener: tokio::net::TcpListener,
    config: roomlight_console::ConsoleConfig,
    control: camera::Control,
    status: tokio::sync::watch::Receiver<camera::RoomStatus>,
    cancel: &CancellationToken,
) -> Result<()> {
    let addr = listener.local_addr()?;
    if !addr.ip().is_loopback() {
        tracing::warn!(%addr, "the console is served in plain HTTP beyond this machine: its token crosses the network in the clear (use a network you trust, or an SSH tunnel to a loopback console)");
    }
    println!("console on http://{addr}/");
    let _ = std::io::stdout().flush();
    let cancel = cancel.clone();
    tokio::spawn(async move {
        if let Err(e) = roomlight_console::serve(listener, config, control, status, cancel).await {
            tracing::error!(error = %e, "the console stopped");
        }
    });
    Ok(())
}

/// Loads the model, connects the camera, listens (calling `listening` with the address once
/// node agents can attach), advertises, and serves until `cancel`, printing the rounds as
/// `process.status_lines` says.
pub async fn serve_camera(
    process: CameraProcess,
    listening: impl FnOnce(SocketAddr),
    cancel: CancellationToken,
) -> Result<()> {
    let (model, camera, extras) = tokio::select! {
        loaded = model_and_camera(&process) => loaded?,
        // Stopped while it waits for its camera.
        () = cancel.cancelled() => return Ok(()),
    };
    let console = match &process.console {
        Some(c) => Some((
            tokio::net::TcpListener::bind(&c.listen)
                .await
                .with_context(|| format!("binding the console's address {}", c.listen))?,
            c.token.clone(),
        )),
        None => None,
    };
    let listener = tokio::net::TcpListener::bind(&process.listen)
        .await
        .with_context(|| format!("binding {}", process.listen))?;
    let addr = listener.local_addr()?;
    listening(addr);
    let room = process.agent.room.clone();
    // Advertised for as long as the agent runs (withdrawn when dropped).
    let _advertisement = match &process.advertise {
        Some(mdns) => Some(
            discovery::advertise(&room, addr, mdns)
                .with_context(|| format!("advertising room {room:?} over mDNS"))?,
        ),
        None => None,
    };
    let survey_file = match &process.source {
        CameraSource::Survey { survey, .. } => Some(survey.clone()),
        CameraSource::Model { .. } => None,
    };
    let model_out = process.agent.model_out.clone();
    let served = camera::serve_room(
        process.agent,
        model,
        camera,
        listener,
        process.tls,
        extras,
        cancel.clone(),
    );
    let (status, handle) = (served.status.clone(), served.handle);
    if let Some((listener, token)) = console {
        let config = roomlight_console::ConsoleConfig {
            token,
            survey: survey_file,
            snapshots: model_out
                .as_deref()
                .and_then(Path::parent)
                .filter(|d| !d.as_os_str().is_empty())
                .map_or_else(|| PathBuf::from("."), Path::to_path_buf),
            model: model_out,
        };
        start_console(listener, config, served.control, served.status, &cancel)?;
    }
    super::systemd::ready(&format!("camera agent of room {room:?} serving on {addr}"));
    super::systemd::with_watchdog(print_rounds(
        status,
        super::StatusPrinter::new(process.status_lines),
        &cancel,
    ))
    .await;
    handle.await.context("the camera agent task")??;
    Ok(())
}

/// Prints the rounds as `printer` makes them, from every change of `status` until `cancel` or
/// the agent's end; a summary due is printed on time even when no round follows it.
async fn print_rounds(
    mut status: tokio::sync::watch::Receiver<camera::RoomStatus>,
    mut printer: super::StatusPrinter,
    cancel: &CancellationToken,
) {
    let print = |lines: &[String]| {
        if lines.is_empty() {
            return;
        }
        let mut out = std::io::stdout().lock();
        for line in lines {
            let _ = writeln!(out, "{line}");
        }
        let _ = out.flush();
    };
    loop {
        let due = printer.due();
        tokio::select! {
            () = cancel.cancelled() => break,
            () = async {
                match due {
                    Some(due) => tokio::time::sleep_until(due.into()).await,
                    None => std::future::pending().await,
                }
            } => {
                if let Some(line) = printer.flush(std::time::Instant::now()) {
                    print(&[line]);
                }
            }
            changed = status.changed() => {
                if changed.is_err() {
                    break;
                }
                let round = {
                    let s = status.borrow();
                    super::Round {
                        line: super::StatusLine {
                            round: s.round,
                            captures: s.captures,
                            objective: s.measured_objective,
                            live: s.live_projectors,
                            calibrated: s.calibrated_hot,
                            averaged: s.averaged,
                        },
                        settled: s.settled,
                    }
                };
                print(&printer.round(round, std::time::Instant::now()));
            }
        }
    }
    if let Some(line) = printer.flush(std::time::Instant::now()) {
        print(&[line]);
    }
}
