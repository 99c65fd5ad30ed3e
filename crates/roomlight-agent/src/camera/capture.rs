//! Captures the nodes can act on: the camera's stale frames discarded first (every frame
//! counted), each capture abandoned after the camera's timeout, patches checked against the
//! model, and with a survey the charts sampled in a whole image. It keeps the camera's health
//! (`faults`): a capture that fails or cannot be used is logged once with the camera's name, the
//! error and the next try, and the state is published in the room's status; the first that
//! works again is logged once too. It knows nothing of peers or rounds.

use super::Shared;
use super::faults::{CameraHealth, CameraState};
use crate::hardware::Camera;
use roomlight_calib::image_io::LinearImage;
use roomlight_core::LinearRgb;
use std::sync::Arc;
use std::time::{Duration, SystemTime};

/// A capture of the model's patches, whether each could be measured, and (with a survey) the
/// whole image they were sampled from.
pub(super) type Measured = (Vec<LinearRgb>, Vec<bool>, Option<Arc<LinearImage>>);

/// The camera, how many frames it has taken, and whether it works.
pub(super) struct Captures<C> {
    camera: C,
    /// Captures taken, stale ones included.
    pub(super) count: u64,
    health: CameraHealth,
    /// When the camera may be tried again after a failure.
    retry_at: Option<tokio::time::Instant>,
}

impl<C: Camera> Captures<C> {
    pub(super) fn new(camera: C) -> Self {
        Self {
            camera,
            count: 0,
            health: CameraHealth::default(),
            retry_at: None,
        }
    }

    /// The camera's state now.
    pub(super) fn state(&self) -> &CameraState {
        self.health.state()
    }

    /// When the camera may be tried again; `None` when it is not failing.
    pub(super) fn retry_at(&self) -> Option<tokio::time::Instant> {
        self.retry_at
    }

    /// Records a capture's outcome: logs and publishes a failure (and when to try again) or
    /// the end of an outage.
    fn record<T>(&mut self, shared: &Shared, outcome: Result<T, String>) -> Option<T> {
        let camera = self.camera.name();
        match outcome {
            Ok(v) => {
                self.retry_at = None;
                if let Some(back) = self.health.succeeded() {
                    let down = SystemTime::now()
                        .duration_since(back.since)
                        .unwrap_or_default();
                    tracing::info!(%camera, failures = back.failures, ?down, "camera back: rounds resume");
                    shared.publish_camera(self.health.state());
                }
                Some(v)
            }
            Err(error) => {
                let retry_in = self.health.failed(error.clone(), SystemTime::now());
                self.retry_at = Some(tokio::time::Instant::now() + retry_in);
                let CameraState::Failing { failures, .. } = self.health.state() else {
                    return None;
                };
                tracing::warn!(%camera, %error, failures, ?retry_in, "capture failed: round abandoned, the projectors keep their light; next try in {retry_in:?}");
                shared.publish_camera(self.health.state());
                None
            }
        }
    }

    /// One capture the nodes can act on: an error when the camera failed or handed over the
    /// wrong number of patches.
    async fn fresh(&mut self, shared: &Shared) -> Result<Vec<LinearRgb>, String> {
        let timeout = self.camera.capture_timeout();
        let y = self
            .latest(shared, timeout, async |c: &mut C| c.capture().await)
            .await?;
        let patches = shared.live().problem.patches();
        if y.len() != patches {
            return Err(format!(
                "the capture has {} patches, the model {patches}",
                y.len()
            ));
        }
        Ok(y)
    }

    /// A capture of the model's patches, with whether each could be measured: with a survey, a
    /// whole image sampled at the charts and the dark target, scaled as the model's rows are
    /// ([`super::Survey::measured`]; a saturated patch, or one an edge crosses, is not
    /// measured: its trimmed mean is not linear in the light); without, the camera's patches,
    /// all taken as measured.
    pub(super) async fn measured(
        &mut self,
        shared: &Shared,
    ) -> Option<(Vec<LinearRgb>, Vec<bool>)> {
        let outcome = self.try_measured(shared).await;
        self.record(shared, outcome).map(|(y, ok, _)| (y, ok))
    }

    /// [`Self::measured`] with the whole image it sampled (`None` without a survey).
    pub(super) async fn measured_image(&mut self, shared: &Shared) -> Option<Measured> {
        let outcome = self.try_measured(shared).await;
        self.record(shared, outcome)
    }

    async fn try_measured(&mut self, shared: &Shared) -> Result<Measured, String> {
        let Some(survey) = &shared.survey else {
            let y = self.fresh(shared).await?;
            let ok = vec![true; y.len()];
            return Ok((y, ok, None));
        };
        let timeout = self.camera.capture_timeout();
        let image = self
            .latest(shared, timeout, async |c: &mut C| c.capture_image().await)
            .await?;
        let samples = survey
            .sample(&image)
            .map_err(|e| format!("the charts could not be sampled: {e}"));
        // The console's view of the room: shared, nothing is copied.
        let image = Arc::new(image);
        shared.publish_photo(image.clone());
        let (means, ok) = survey.measured(&samples?)?;
        let patches = shared.live().problem.patches();
        if means.len() != patches {
            return Err(format!(
                "the survey has {} patches, the model {patches}",
                means.len()
            ));
        }
        Ok((means, ok, Some(image)))
    }

    /// One whole image exposed `exposure` times as long as normal (in the units of a normal
    /// one), the camera's stale frames discarded first (every frame counted).
    pub(super) async fn image_exposed(
        &mut self,
        shared: &Shared,
        exposure: f32,
    ) -> Option<LinearImage> {
        // A longer exposure may take as much longer.
        let timeout = self.camera.capture_timeout().mul_f32(exposure.max(1.0));
        let outcome = self
            .latest(shared, timeout, async move |c: &mut C| {
                c.capture_image_exposed(exposure).await
            })
            .await;
        self.record(shared, outcome)
    }

    /// A whole photograph for the console (between rounds; every frame counted). Its failure
    /// is the console's answer and does not count against the camera's health: a camera that
    /// gives only patches (the synthetic room's) still runs the rounds.
    pub(super) async fn photograph(
        &mut self,
        shared: &Shared,
    ) -> Result<LinearImage, super::operator::Refused> {
        let timeout = self.camera.capture_timeout();
        self.latest(shared, timeout, async |c: &mut C| c.capture_image().await)
            .await
            .map_err(super::operator::Refused::Camera)
    }

    /// The camera's limits, for calibration.
    pub(super) fn limits(&self) -> roomlight_calib::rig::CameraLimits {
        self.camera.limits()
    }

    /// The last of `stale_frames + 1` captures taken with `take` (every one counted), each
    /// abandoned after `timeout`; an error naming the first that failed or hung.
    async fn latest<T>(
        &mut self,
        shared: &Shared,
        timeout: Duration,
        mut take: impl AsyncFnMut(&mut C) -> Result<T, crate::AgentError>,
    ) -> Result<T, String> {
        let mut last = None;
        for _ in 0..=shared.config.stale_frames {
            match tokio::time::timeout(timeout, take(&mut self.camera)).await {
                Ok(Ok(v)) => {
                    self.count += 1;
                    last = Some(v);
                }
                Ok(Err(e)) => return Err(e.to_string()),
                Err(_) => return Err(format!("no capture within {timeout:?} (hung)")),
            }
        }
        last.ok_or_else(|| "no capture taken".to_string())
    }
}
