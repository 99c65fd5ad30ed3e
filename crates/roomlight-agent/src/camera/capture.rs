//! Captures the nodes can act on: the camera's stale frames discarded first (every frame
//! counted), patches checked against the model, and with a survey the charts sampled in a whole
//! image. It knows nothing of peers or rounds.

use super::Shared;
use crate::hardware::Camera;
use roomlight_calib::image_io::LinearImage;
use roomlight_core::LinearRgb;

/// The camera and how many frames it has taken.
pub(super) struct Captures<C> {
    camera: C,
    /// Captures taken, stale ones included.
    pub(super) count: u64,
}

impl<C: Camera> Captures<C> {
    pub(super) fn new(camera: C) -> Self {
        Self { camera, count: 0 }
    }

    /// One capture the nodes can act on. `None` when the camera failed or handed over the wrong
    /// number of patches (logged).
    async fn fresh(&mut self, shared: &Shared) -> Option<Vec<LinearRgb>> {
        let y = self
            .latest(shared, async |c: &mut C| c.capture().await)
            .await?;
        let patches = shared.live().problem.patches();
        if y.len() != patches {
            tracing::error!(
                got = y.len(),
                expected = patches,
                "capture has the wrong number of patches"
            );
            return None;
        }
        Some(y)
    }

    /// A capture of the model's patches, with whether each could be measured: with a survey, a
    /// whole image sampled at the charts (a saturated patch, or one an edge crosses, is not
    /// measured: its trimmed mean is not linear in the light); without, the camera's patches,
    /// all taken as measured.
    pub(super) async fn measured(
        &mut self,
        shared: &Shared,
    ) -> Option<(Vec<LinearRgb>, Vec<bool>)> {
        let Some(survey) = &shared.survey else {
            let y = self.fresh(shared).await?;
            let ok = vec![true; y.len()];
            return Some((y, ok));
        };
        let image = self.image(shared).await?;
        let samples =
            match roomlight_calib::charts::sample_charts(&image, &survey.corners, &survey.sample) {
                Ok(s) => s,
                Err(e) => {
                    tracing::warn!(error = %e, "the charts could not be sampled");
                    return None;
                }
            };
        let mut means = Vec::with_capacity(survey.patches.len());
        let mut ok = Vec::with_capacity(survey.patches.len());
        for &i in &survey.patches {
            let Some(sample) = samples.get(i) else {
                tracing::error!(
                    patch = i,
                    charts = samples.len(),
                    "the survey names a patch the charts lack"
                );
                return None;
            };
            means.push(sample.mean);
            ok.push(sample.status == roomlight_calib::charts::PatchStatus::Ok);
        }
        let patches = shared.live().problem.patches();
        if means.len() != patches {
            tracing::error!(
                surveyed = means.len(),
                expected = patches,
                "the survey's patches do not match the model's"
            );
            return None;
        }
        Some((means, ok))
    }

    /// One whole image, the camera's stale frames discarded first (every frame counted).
    pub(super) async fn image(&mut self, shared: &Shared) -> Option<LinearImage> {
        self.latest(shared, async |c: &mut C| c.capture_image().await)
            .await
    }

    /// One whole image exposed `exposure` times as long as normal (in the units of a normal
    /// one), the camera's stale frames discarded first (every frame counted).
    pub(super) async fn image_exposed(
        &mut self,
        shared: &Shared,
        exposure: f32,
    ) -> Option<LinearImage> {
        self.latest(shared, async move |c: &mut C| {
            c.capture_image_exposed(exposure).await
        })
        .await
    }

    /// The camera's limits, for calibration.
    pub(super) fn limits(&self) -> roomlight_calib::rig::CameraLimits {
        self.camera.limits()
    }

    /// The last of `stale_frames + 1` captures taken with `take` (every one counted); `None`
    /// when one failed (logged).
    async fn latest<T>(
        &mut self,
        shared: &Shared,
        mut take: impl AsyncFnMut(&mut C) -> Result<T, crate::AgentError>,
    ) -> Option<T> {
        let mut last = None;
        for _ in 0..=shared.config.stale_frames {
            match take(&mut self.camera).await {
                Ok(v) => {
                    self.count += 1;
                    last = Some(v);
                }
                Err(e) => {
                    tracing::warn!(error = %e, "capture failed");
                    return None;
                }
            }
        }
        last
    }
}
