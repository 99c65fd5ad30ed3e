//! The camera agent's camera on real hardware: `HwCamera` implements
//! `roomlight_agent::hardware::Camera` over any backend. `capture_image` is the linear image;
//! `capture` samples the survey's charts with `roomlight_calib::charts::sample_charts` (the
//! code every image camera uses) and reduces them to the model's patches. Masked pixels
//! (saturated, under-exposed) become NaN before sampling, so a patch touching one is flagged
//! and refused, never averaged. It must not know rounds or the wire.

use crate::error::CameraError;
use crate::radiometry::{Linearized, Radiometry};
use crate::spec::CameraConfig;
use crate::{Backend, open_backend};
use roomlight_agent::AgentError;
use roomlight_calib::charts::{ChartCorners, PatchStatus, SampleConfig, sample_charts};
use roomlight_calib::image_io::LinearImage;
use roomlight_core::LinearRgb;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

/// Where the model's patches are in the camera's image.
#[derive(Debug, Clone)]
pub struct Charts {
    pub corners: Arc<Vec<ChartCorners>>,
    /// Room patch index of each model patch.
    pub patches: Arc<Vec<usize>>,
    pub sample: SampleConfig,
}

/// A real camera with its radiometry, for the camera agent.
#[derive(Clone)]
pub struct HwCamera {
    backend: Arc<Mutex<Box<dyn Backend>>>,
    name: String,
    radiometry: Arc<Radiometry>,
    timeout: Duration,
    charts: Option<Charts>,
}

impl std::fmt::Debug for HwCamera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HwCamera")
            .field("name", &self.name)
            .field("timeout", &self.timeout)
            .finish_non_exhaustive()
    }
}

impl HwCamera {
    /// Opens the configured camera (validated first) and loads its dark frame.
    pub fn open(config: &CameraConfig) -> Result<Self, CameraError> {
        config.validate()?;
        let backend = open_backend(config)?;
        let mut radiometry = Radiometry::new(
            &config.response,
            config.saturated_code,
            config.underexposed_code,
        );
        if let Some(path) = &config.dark_frame {
            let dark = LinearImage::load_png(
                path,
                roomlight_calib::image_io::Encoding::Linear,
                roomlight_calib::image_io::Depth::Sixteen,
            )
            .map_err(|e| CameraError::Decode {
                path: path.clone(),
                reason: format!("dark frame: {e}"),
            })?;
            radiometry = radiometry.with_dark_frame(dark);
        }
        Ok(Self::new(backend, radiometry, config.timeout()))
    }

    /// A camera over any backend (tests use fakes).
    pub fn new(backend: Box<dyn Backend>, radiometry: Radiometry, timeout: Duration) -> Self {
        Self {
            name: backend.name().to_string(),
            backend: Arc::new(Mutex::new(backend)),
            radiometry: Arc::new(radiometry),
            timeout,
            charts: None,
        }
    }

    /// Samples `charts` for [`roomlight_agent::hardware::Camera::capture`].
    pub fn with_charts(mut self, charts: Charts) -> Self {
        self.charts = Some(charts);
        self
    }

    /// One capture made linear, with its mask and the exposure used; every capture has the
    /// configured timeout.
    pub async fn capture_linear(&self) -> Result<(Linearized, Option<f64>), CameraError> {
        let this = self.clone();
        let deadline = Instant::now() + self.timeout;
        tokio::task::spawn_blocking(move || {
            let frame = this
                .backend
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .capture(deadline)?;
            let linear = this.radiometry.linearize(&frame, &this.name)?;
            Ok((linear, frame.exposure_s))
        })
        .await
        .map_err(|e| CameraError::Gone {
            camera: self.name.clone(),
            reason: format!("capture task: {e}"),
        })?
    }

    /// The model's patches in one capture; a patch that touches a masked pixel is refused.
    pub async fn patches(&self) -> Result<Vec<LinearRgb>, String> {
        let charts = self
            .charts
            .clone()
            .ok_or_else(|| format!("camera {}: no charts to sample", self.name))?;
        let (mut linear, _) = self.capture_linear().await.map_err(|e| e.to_string())?;
        for (p, &ok) in linear.image.pixels.iter_mut().zip(&linear.usable) {
            if !ok {
                *p = [f32::NAN; 3];
            }
        }
        let samples = sample_charts(&linear.image, &charts.corners, &charts.sample)
            .map_err(|e| format!("charts: {e}"))?;
        charts
            .patches
            .iter()
            .map(|&i| {
                let s = samples
                    .get(i)
                    .ok_or_else(|| format!("patch {i}: the charts have {}", samples.len()))?;
                match s.status {
                    PatchStatus::Ok | PatchStatus::NonUniform => Ok(s.mean),
                    PatchStatus::Saturated => Err(format!(
                        "camera {}: patch {i} has saturated or under-exposed pixels; change \
                         the exposure",
                        self.name
                    )),
                    other => Err(format!("camera {}: patch {i}: {other:?}", self.name)),
                }
            })
            .collect()
    }
}

/// How much longer than the backend's own timeout the camera agent waits before it abandons a
/// capture as hung: the backend's error, which says more, comes first.
const AGENT_TIMEOUT_MARGIN: Duration = Duration::from_secs(2);

impl roomlight_agent::hardware::Camera for HwCamera {
    fn name(&self) -> &str {
        &self.name
    }

    fn capture_timeout(&self) -> Duration {
        self.timeout + AGENT_TIMEOUT_MARGIN
    }

    fn capture(&mut self) -> impl Future<Output = Result<Vec<LinearRgb>, AgentError>> + Send {
        let this = self.clone();
        async move { this.patches().await.map_err(AgentError::Protocol) }
    }

    fn capture_image(&mut self) -> impl Future<Output = Result<LinearImage, AgentError>> + Send {
        let this = self.clone();
        async move {
            this.capture_linear()
                .await
                .map(|(l, _)| l.image)
                .map_err(|e| AgentError::Protocol(e.to_string()))
        }
    }

    fn limits(&self) -> roomlight_calib::rig::CameraLimits {
        roomlight_calib::rig::CameraLimits {
            saturation: self.radiometry.saturation(),
            longest_exposure: 1.0,
        }
    }
}
