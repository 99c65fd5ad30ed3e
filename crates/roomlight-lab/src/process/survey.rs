//! The camera agent's model for calibration over the wire: the survey checked against the
//! rendered room, and the room's black and target measured through the charts before any
//! projector joins (or, for a restarted agent, the model it wrote resumed). The room's LEDs are
//! switched through the rendered room; the photographs are its camera's or a real camera's
//! (`eye`).

use super::camera::AnyCamera;
use super::files::{ModelFile, SurveyFile};
use crate::rendered::{Client, RenderedCamera};
use anyhow::{Context, Result, bail};
use roomlight_agent::camera::{self, RoomModel};
use roomlight_agent::hardware::Camera as _;
use roomlight_calib::procedure::Target;
use roomlight_camera::{Charts, HwCamera};
use roomlight_proto::v1;
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

/// A survey checked against the room it was made of, with its target as a camera mask.
struct Checked {
    survey: SurveyFile,
    target_mask: Vec<bool>,
    presets: Vec<String>,
}

impl Checked {
    /// The camera agent's survey over `patches` (room patch indices).
    fn for_patches(&self, patches: Vec<usize>) -> camera::Survey {
        camera::Survey {
            corners: self.survey.corners.clone(),
            sample: self.survey.sample,
            target_mask: self.target_mask.clone(),
            patches,
        }
    }

    /// The camera sampling `patches`: the rendered room's through `client`, or `eye`.
    fn camera(&self, client: Client, patches: Vec<usize>, eye: Option<&HwCamera>) -> AnyCamera {
        match eye {
            None => AnyCamera::Rendered(RenderedCamera::new(
                client,
                self.survey.corners.clone(),
                patches,
                self.survey.sample,
            )),
            Some(eye) => AnyCamera::Real(eye.clone().with_charts(Charts {
                corners: Arc::new(self.survey.corners.clone()),
                patches: Arc::new(patches),
                sample: self.survey.sample,
            })),
        }
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
    resume: Option<(&Path, ModelFile)>,
    client: Client,
    eye: Option<HwCamera>,
) -> Result<(RoomModel, AnyCamera)> {
    let checked = check(survey_path, &client).await?;
    match resume {
        Some((path, model)) => resumed(&checked, path, model, client, eye.as_ref()),
        None => measured(&checked, preset, client, eye.as_ref()).await,
    }
}

async fn check(survey_path: &Path, client: &Client) -> Result<Checked> {
    let survey = super::files::load_survey(survey_path)?;
    let target_mask = survey.target_mask();
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
    Ok(Checked {
        survey,
        target_mask,
        presets: description.presets,
    })
}

/// The model a camera agent calibrating over the wire wrote, checked against the survey.
fn resumed(
    checked: &Checked,
    path: &Path,
    model: ModelFile,
    client: Client,
    eye: Option<&HwCamera>,
) -> Result<(RoomModel, AnyCamera)> {
    let patches = model.patches.clone().with_context(|| {
        format!(
            "{}: no patches (not written by a camera agent calibrating over the wire)",
            path.display()
        )
    })?;
    let charts = checked.survey.corners.len()
        * roomlight_calib::charts::COLUMNS
        * roomlight_calib::charts::ROWS;
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
    let camera = checked.camera(client, patches.clone(), eye);
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
    client: Client,
    eye: Option<&HwCamera>,
) -> Result<(RoomModel, AnyCamera)> {
    let preset = match preset {
        Some(p) if checked.presets.iter().any(|q| q == p) => p.to_string(),
        Some(p) => bail!("preset {p:?}: the room has {}", checked.presets.join(", ")),
        None => checked
            .presets
            .first()
            .cloned()
            .context("the room has no LED preset to reproduce")?,
    };
    let lights = RenderedCamera::new(
        client.clone(),
        Vec::new(),
        Vec::new(),
        checked.survey.sample,
    );
    let mut camera = checked.camera(client.clone(), Vec::new(), eye);
    let survey = &checked.survey;
    let mut photograph = async || -> Result<Vec<roomlight_calib::charts::PatchSample>> {
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
        roomlight_calib::charts::sample_charts(&image, &survey.corners, &survey.sample)
            .context("sampling the charts")
    };
    lights.set_lights("").await?;
    let black = photograph().await?;
    lights.set_lights(&preset).await?;
    let lit = photograph().await?;
    lights.set_lights("").await?;
    // The model's patches and problem as the in-process pipeline builds them; no projector
    // has joined, so no columns yet.
    let target = Target::from_samples(&black, &lit)
        .context("no chart patch could be measured under both the LEDs and the dark")?;
    let problem = target.problem(Vec::new())?;
    let patches = target.patches;
    println!(
        "survey: {} of {} patches measured, target from preset {preset}",
        patches.len(),
        lit.len()
    );
    let camera = checked.camera(client, patches.clone(), eye);
    let model = RoomModel {
        problem,
        owners: HashMap::new(),
        start: None,
        hot: Default::default(),
        survey: Some(checked.for_patches(patches)),
    };
    Ok((model, camera))
}
