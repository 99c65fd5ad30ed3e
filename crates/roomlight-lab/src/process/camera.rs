//! `roomlight camera` on simulated hardware: the camera agent's model and camera from the files
//! of a calibrated room or a survey, served until cancelled, one status line per round.

use super::files::{ChartsFile, ModelFile, load_model, read_json};
use super::survey::survey_model;
use crate::rendered::RenderedCamera;
use anyhow::{Context, Result, bail};
use roomlight_agent::AgentError;
use roomlight_agent::camera::{self, CameraConfig, RoomModel};
use roomlight_agent::discovery::{self, MdnsConfig};
use roomlight_agent::remote::RemoteCamera;
use roomlight_calib::image_io::LinearImage;
use roomlight_core::LinearRgb;
use std::io::Write;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::pin::Pin;
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
    /// node agent as it joins; `preset` is the LED preset reproduced (default: the first).
    Survey {
        survey: PathBuf,
        preset: Option<String>,
    },
}

/// A camera agent on simulated hardware.
#[derive(Debug, Clone)]
pub struct CameraProcess {
    pub agent: CameraConfig,
    /// The `roomlight sim` process that serves the camera.
    pub hardware: String,
    pub source: CameraSource,
    /// Where node agents attach.
    pub listen: String,
    /// Advertise the agent over mDNS.
    pub advertise: Option<MdnsConfig>,
}

/// The camera agent's camera: the synthetic room's patches, or a rendered room's images
/// sampled at the charts.
enum AnyCamera {
    Synthetic(RemoteCamera),
    Rendered(RenderedCamera),
}

impl roomlight_agent::hardware::Camera for AnyCamera {
    fn capture_image(&mut self) -> impl Future<Output = Result<LinearImage, AgentError>> + Send {
        let capture: Pin<Box<dyn Future<Output = _> + Send + '_>> = match self {
            Self::Synthetic(c) => Box::pin(c.capture_image()),
            Self::Rendered(c) => Box::pin(c.capture_image()),
        };
        capture
    }

    fn capture(&mut self) -> impl Future<Output = Result<Vec<LinearRgb>, AgentError>> + Send {
        let capture: Pin<Box<dyn Future<Output = _> + Send + '_>> = match self {
            Self::Synthetic(c) => Box::pin(c.capture()),
            Self::Rendered(c) => Box::pin(c.capture()),
        };
        capture
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
    hardware: &str,
) -> Result<(RoomModel, AnyCamera)> {
    let model = load_model(model_path)?;
    let camera = match charts {
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
            AnyCamera::Rendered(RenderedCamera::new(
                connect_rendered(hardware).await?,
                charts.corners,
                charts.patches,
                charts.sample,
            ))
        }
        None => AnyCamera::Synthetic(
            RemoteCamera::connect(hardware.to_string())
                .await
                .with_context(|| format!("connecting to the camera at {hardware}"))?,
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

async fn model_and_camera(process: &CameraProcess) -> Result<(RoomModel, AnyCamera)> {
    match &process.source {
        CameraSource::Model { model, charts } => {
            from_model(model, charts.as_deref(), &process.hardware).await
        }
        CameraSource::Survey { survey, preset } => {
            // The model this camera agent wrote before it was restarted, if any.
            let resume: Option<(&Path, ModelFile)> = match &process.agent.model_out {
                Some(out) if out.exists() => Some((out.as_path(), load_model(out)?)),
                _ => None,
            };
            let client = connect_rendered(&process.hardware).await?;
            let (model, camera) = survey_model(survey, preset.as_deref(), resume, client).await?;
            Ok((model, AnyCamera::Rendered(camera)))
        }
    }
}

/// Loads the model, connects the camera, listens (calling `listening` with the address once
/// node agents can attach), advertises, and serves until `cancel`, printing one line per round.
pub async fn serve_camera(
    process: CameraProcess,
    listening: impl FnOnce(SocketAddr),
    cancel: CancellationToken,
) -> Result<()> {
    let (model, camera) = model_and_camera(&process).await?;
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
    let (mut status, handle) =
        camera::serve(process.agent, model, camera, listener, cancel.clone());
    loop {
        tokio::select! {
            () = cancel.cancelled() => break,
            changed = status.changed() => {
                if changed.is_err() {
                    break;
                }
                let s = status.borrow().clone();
                println!(
                    "round {} captures {} objective {:.6e} live {} calibrated {}",
                    s.round, s.captures, s.measured_objective, s.live_projectors, s.calibrated_hot
                );
                let _ = std::io::stdout().flush();
            }
        }
    }
    handle.await.context("the camera agent task")??;
    Ok(())
}
