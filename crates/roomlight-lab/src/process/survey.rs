//! The camera agent's model for calibration over the wire: the survey checked against the
//! rendered room, and the room's black and target measured through the charts before any
//! projector joins (or, for a restarted agent, the model it wrote resumed). The room's LEDs are
//! switched through the rendered room; the photographs are its camera's or a real camera's
//! (`eye`).

use super::camera::AnyCamera;
use super::files::{ModelFile, SurveyFile};
use super::lights::ManualLights;
use crate::rendered::{Client, RenderedCamera};
use anyhow::{Context, Result, bail};
use roomlight_agent::camera::{self, RoomModel};
use roomlight_agent::hardware::Camera as _;
use roomlight_camera::{Charts, HwCamera};
use roomlight_proto::v1;
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

/// The room a survey is made of, and how its LEDs are switched.
#[derive(Debug, Clone)]
pub enum SurveyRoom {
    /// A rendered room (`roomlight sim`): its service describes it, photographs it (unless a
    /// real camera does) and switches its LEDs.
    Rendered(Client),
    /// A physical room: a real camera photographs it and a person switches its LEDs (the
    /// preset is the name of what they switch on).
    Physical(ManualLights),
}

/// A survey checked against the room it was made of, as the camera agent takes it.
struct Checked {
    survey: SurveyFile,
    /// The camera agent's survey (no patches yet): the target as a camera mask, and its
    /// patches when it is kept dark.
    agent: camera::Survey,
    presets: Vec<String>,
    /// Where the rendered room's camera clips, as it describes it (NaN: a physical room).
    saturation: f32,
}

impl Checked {
    fn new(
        survey: SurveyFile,
        path: &Path,
        presets: Vec<String>,
        saturation: f32,
        dark_weight: f64,
    ) -> Result<Self> {
        let agent = camera::Survey::new(
            survey.corners.clone(),
            survey.sample,
            survey.target_mask(),
            (survey.camera_width, survey.camera_height),
            dark_weight,
        )
        .with_context(|| format!("{}", path.display()))?;
        if dark_weight > 0.0 && agent.dark_patches().is_empty() && !survey.target_pixels.is_empty()
        {
            // Its luminaire pixels are black all the same; only their reflections go unweighed.
            tracing::warn!(
                survey = %path.display(),
                pixels = survey.target_pixels.len(),
                "the target is too small for a patch of 4 pixels (after a pixel's erosion): \
                 the light reflected onto it is not weighed (dark_target_weight {dark_weight})"
            );
        }
        Ok(Self {
            survey,
            agent,
            presets,
            saturation,
        })
    }

    /// The survey at the dark-target weight a model file was measured at (its target patches'
    /// rows are scaled by it; absent, as before the weight was written: 0), so that a resumed
    /// room goes on as it was; the config's weight applies once the room is surveyed again,
    /// and a difference is warned about. A weight out of range is an error naming `path`.
    fn at_weight(&mut self, measured: Option<f64>, path: &Path) -> Result<()> {
        let weight = measured.unwrap_or(0.0);
        let configured = self.agent.dark_weight();
        if weight.to_bits() == configured.to_bits() {
            return Ok(());
        }
        self.agent = camera::Survey::new(
            self.survey.corners.clone(),
            self.survey.sample,
            self.agent.target_mask.clone(),
            (self.survey.camera_width, self.survey.camera_height),
            weight,
        )
        .with_context(|| format!("{}", path.display()))?;
        tracing::warn!(
            model = %path.display(),
            "the model was measured with dark_target_weight {weight}, the config asks for \
             {configured}: resumed at {weight}; move the model away to survey the room again \
             at {configured}"
        );
        Ok(())
    }

    /// The camera agent's survey over `patches` (room patch indices).
    fn for_patches(&self, patches: Vec<usize>) -> camera::Survey {
        self.agent.clone().with_patches(patches)
    }

    /// The camera sampling `patches`' chart patches: `eye`, else the rendered room's. (With a
    /// survey the camera agent samples whole photographs itself, the target's patches too.)
    fn camera(
        &self,
        room: &SurveyRoom,
        patches: Vec<usize>,
        eye: Option<&HwCamera>,
    ) -> Result<AnyCamera> {
        let patches: Vec<usize> = patches
            .into_iter()
            .filter(|&i| !self.agent.is_dark(i))
            .collect();
        Ok(match (eye, room) {
            (Some(eye), _) => AnyCamera::Real(eye.clone().with_charts(Charts {
                corners: Arc::new(self.survey.corners.clone()),
                patches: Arc::new(patches),
                sample: self.survey.sample,
            })),
            (None, SurveyRoom::Rendered(client)) => AnyCamera::Rendered(
                RenderedCamera::new(
                    client.clone(),
                    self.survey.corners.clone(),
                    patches,
                    self.survey.sample,
                )
                .with_saturation(self.saturation),
            ),
            (None, SurveyRoom::Physical(_)) => {
                bail!("a physical room is photographed by a real camera")
            }
        })
    }
}

/// Calibration over the wire, before any projector: the survey, and the room's black level
/// (LEDs off, projectors dark) and target (the LED preset) measured through the charts; the
/// model has no nodes yet and admits every projector that says its resolution. With `resume`
/// (the model a camera agent calibrating over the wire wrote, e.g. before it was restarted)
/// nothing is measured: the room is lit by the node agents, which keep their light, and the
/// model goes on from where it was (new projectors are still calibrated as they join).
pub(super) async fn survey_model(
    survey_path: &Path,
    preset: Option<&str>,
    dark_weight: f64,
    resume: Option<(&Path, ModelFile)>,
    room: SurveyRoom,
    eye: Option<HwCamera>,
) -> Result<(RoomModel, AnyCamera, camera::Extras)> {
    let mut checked = match &room {
        SurveyRoom::Rendered(client) => check(survey_path, client, dark_weight).await?,
        SurveyRoom::Physical(_) => {
            // Nothing describes a physical room: the camera's size is checked on each
            // photograph, and the preset is what the installer names.
            let survey = super::files::load_survey(survey_path)?;
            let presets = vec![preset.unwrap_or("the room's LEDs").to_string()];
            Checked::new(survey, survey_path, presets, f32::NAN, dark_weight)?
        }
    };
    // The config's preset, else the one the console saved in the survey.
    let saved = checked.survey.preset.clone();
    let preset = preset.or(saved.as_deref());
    let (model, camera, preset, photographs) = match resume {
        Some((path, model)) => {
            let (model, camera) = resumed(&mut checked, path, model, &room, eye.as_ref())?;
            (model, camera, preset.map(str::to_string), None)
        }
        None => {
            let (model, camera, preset, photographs) =
                measured(&checked, preset, &room, eye.as_ref()).await?;
            (model, camera, Some(preset), Some(photographs))
        }
    };
    let lights = SurveyLights {
        room,
        presets: checked.presets.clone(),
        sample: checked.survey.sample,
    };
    let extras = camera::Extras {
        lights: Some(Arc::new(lights)),
        preset,
        photographs,
    };
    Ok((model, camera, extras))
}

/// The room's LEDs as the camera agent switches them for the console's preset.
struct SurveyLights {
    room: SurveyRoom,
    presets: Vec<String>,
    sample: roomlight_calib::charts::SampleConfig,
}

impl camera::Lights for SurveyLights {
    fn presets(&self) -> Vec<String> {
        self.presets.clone()
    }

    fn switch(
        &self,
        preset: Option<String>,
    ) -> std::pin::Pin<Box<dyn Future<Output = Result<(), String>> + Send + '_>> {
        Box::pin(async move {
            switch_room(&self.room, self.sample, preset.as_deref())
                .await
                .map_err(|e| format!("{e:#}"))
        })
    }
}

async fn check(survey_path: &Path, client: &Client, dark_weight: f64) -> Result<Checked> {
    let survey = super::files::load_survey(survey_path)?;
    let description = client
        .clone()
        .describe(v1::DescribeRequest {})
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
    Checked::new(
        survey,
        survey_path,
        description.presets,
        description.camera_saturation,
        dark_weight,
    )
}

/// The model a camera agent calibrating over the wire wrote, checked against the survey (and
/// resumed at the dark-target weight it was measured at, whatever the config asks).
fn resumed(
    checked: &mut Checked,
    path: &Path,
    model: ModelFile,
    room: &SurveyRoom,
    eye: Option<&HwCamera>,
) -> Result<(RoomModel, AnyCamera)> {
    let patches = model.patches.clone().with_context(|| {
        format!(
            "{}: no patches (not written by a camera agent calibrating over the wire)",
            path.display()
        )
    })?;
    checked.at_weight(model.dark_target_weight, path)?;
    let surveyed = checked.agent.room_patches();
    if patches.len() != model.problem.patches() || patches.iter().any(|&i| i >= surveyed) {
        bail!(
            "{}: {} patches for a model of {}, of {surveyed} surveyed",
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
    let camera = checked.camera(room, patches.clone(), eye)?;
    let model = RoomModel {
        problem: model.problem,
        owners: model.owners,
        start: model.start,
        hot: Default::default(),
        survey: Some(checked.for_patches(patches)),
    };
    Ok((model, camera))
}

/// A model without nodes: the room's black and the preset's target through the charts.
async fn measured(
    checked: &Checked,
    preset: Option<&str>,
    room: &SurveyRoom,
    eye: Option<&HwCamera>,
) -> Result<(RoomModel, AnyCamera, String, camera::SurveyPhotographs)> {
    let preset = match preset {
        Some(p) if checked.presets.iter().any(|q| q == p) => p.to_string(),
        Some(p) => bail!("preset {p:?}: the room has {}", checked.presets.join(", ")),
        None => checked
            .presets
            .first()
            .cloned()
            .context("the room has no LED preset to reproduce")?,
    };
    let mut camera = checked.camera(room, Vec::new(), eye)?;
    let survey = &checked.survey;
    let mut photograph = async || -> Result<roomlight_calib::image_io::LinearImage> {
        let image = camera
            .capture_image()
            .await
            .context("photographing the room")?;
        if (image.width, image.height) != (survey.camera_width, survey.camera_height) {
            bail!(
                "a photograph of {}x{}: the survey's camera is {}x{}",
                image.width,
                image.height,
                survey.camera_width,
                survey.camera_height
            );
        }
        Ok(image)
    };
    let sample = |image: &roomlight_calib::image_io::LinearImage| {
        checked.agent.sample(image).context("sampling the charts")
    };
    switch(room, checked, None).await?;
    let dark = photograph().await?;
    let black = sample(&dark)?;
    switch(room, checked, Some(&preset)).await?;
    let leds = photograph().await?;
    let lit = sample(&leds)?;
    // The projectors replace the LEDs from here on.
    switch(room, checked, None).await?;
    // The model's patches and problem as the in-process pipeline builds them; no projector
    // has joined, so no columns yet.
    let (problem, agent) = checked
        .agent
        .clone()
        .model(&black, &lit)
        .context("no chart patch could be measured under both the LEDs and the dark")?;
    let patches = agent.patches.clone();
    let kept_dark = patches.iter().filter(|&&i| agent.is_dark(i)).count();
    let on_target = if kept_dark > 0 {
        format!(
            " ({kept_dark} on the target, kept dark at weight {})",
            agent.dark_weight()
        )
    } else {
        String::new()
    };
    println!(
        "survey: {} of {} patches measured{on_target}, target from preset {preset}",
        patches.len(),
        lit.len(),
    );
    let camera = checked.camera(room, patches.clone(), eye)?;
    let model = RoomModel {
        problem,
        owners: HashMap::new(),
        start: None,
        hot: Default::default(),
        survey: Some(agent),
    };
    // Per-pixel shading starts from them: its passes follow the bring-up.
    let photographs = camera::SurveyPhotographs { dark, leds };
    Ok((model, camera, preset, photographs))
}

/// Switches the room's LEDs to `preset` (`None`: off).
async fn switch(room: &SurveyRoom, checked: &Checked, preset: Option<&str>) -> Result<()> {
    switch_room(room, checked.survey.sample, preset).await
}

/// [`switch`] with the sampling only.
async fn switch_room(
    room: &SurveyRoom,
    sample: roomlight_calib::charts::SampleConfig,
    preset: Option<&str>,
) -> Result<()> {
    match room {
        SurveyRoom::Rendered(client) => {
            RenderedCamera::new(client.clone(), Vec::new(), Vec::new(), sample)
                .set_lights(preset.unwrap_or(""))
                .await?;
            Ok(())
        }
        SurveyRoom::Physical(lights) => lights.switch(preset.is_some(), preset.unwrap_or("")).await,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 20 × 20 camera without charts and a 10 × 10 target, its survey at `weight`.
    fn checked(weight: f64) -> Checked {
        let target_pixels = (0..400u32)
            .filter(|i| (4..14).contains(&(i % 20)) && (6..16).contains(&(i / 20)))
            .collect();
        let survey = SurveyFile {
            camera_width: 20,
            camera_height: 20,
            corners: Vec::new(),
            sample: roomlight_calib::charts::SampleConfig::default(),
            target_pixels,
            target_polygons: Vec::new(),
            preset: None,
        };
        Checked::new(survey, Path::new("s.json"), Vec::new(), f32::NAN, weight).expect("checked")
    }

    #[test]
    fn a_model_resumes_at_the_dark_weight_it_was_measured_at() {
        let path = Path::new("model.json");
        let mut same = checked(1.0);
        same.at_weight(Some(1.0), path).expect("same weight");
        assert_eq!(
            (same.agent.dark_weight(), same.agent.dark_patches()),
            (1.0, 0..4)
        );
        // Written before the weight was: resumed without target patches.
        let mut old = checked(1.0);
        old.at_weight(None, path).expect("no weight written");
        assert_eq!(
            (old.agent.dark_weight(), old.agent.dark_patches()),
            (0.0, 0..0)
        );
        let mut other = checked(0.0);
        other.at_weight(Some(10.0), path).expect("another weight");
        assert_eq!(other.agent.dark_weight().to_bits(), 10.0f64.to_bits());
        assert_eq!(other.agent.dark_patches(), 0..4);
        for bad in [f64::NAN, -1.0, 1e9] {
            let e = format!(
                "{:#}",
                checked(1.0)
                    .at_weight(Some(bad), path)
                    .expect_err("refused")
            );
            assert!(
                e.contains("model.json") && e.contains("dark_target_weight"),
                "{e}"
            );
        }
    }
}
