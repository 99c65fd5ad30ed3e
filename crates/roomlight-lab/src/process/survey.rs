//! The camera agent's model for calibration over the wire: the survey checked against the
//! rendered room, and the room's black and target measured through the charts before any
//! projector joins (or, for a restarted agent, the model it wrote resumed).

use super::files::{ModelFile, SurveyFile, read_json};
use crate::rendered::{Client, RenderedCamera};
use anyhow::{Context, Result, bail};
use roomlight_agent::camera::{self, RoomModel};
use roomlight_calib::procedure::Target;
use roomlight_proto::v1;
use std::collections::HashMap;
use std::path::Path;

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

    fn camera(&self, client: Client, patches: Vec<usize>) -> RenderedCamera {
        RenderedCamera::new(
            client,
            self.survey.corners.clone(),
            patches,
            self.survey.sample,
        )
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
) -> Result<(RoomModel, RenderedCamera)> {
    let checked = check(survey_path, &client).await?;
    match resume {
        Some((path, model)) => resumed(&checked, path, model, client),
        None => measured(&checked, preset, client).await,
    }
}

async fn check(survey_path: &Path, client: &Client) -> Result<Checked> {
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
) -> Result<(RoomModel, RenderedCamera)> {
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
    let camera = checked.camera(client, patches.clone());
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
) -> Result<(RoomModel, RenderedCamera)> {
    let preset = match preset {
        Some(p) if checked.presets.iter().any(|q| q == p) => p.to_string(),
        Some(p) => bail!("preset {p:?}: the room has {}", checked.presets.join(", ")),
        None => checked
            .presets
            .first()
            .cloned()
            .context("the room has no LED preset to reproduce")?,
    };
    let camera = checked.camera(client, Vec::new());
    let survey = &checked.survey;
    let sample = |image| {
        roomlight_calib::charts::sample_charts(&image, &survey.corners, &survey.sample)
            .context("sampling the charts")
    };
    camera.set_lights("").await?;
    let black = sample(camera.image().await?)?;
    camera.set_lights(&preset).await?;
    let lit = sample(camera.image().await?)?;
    camera.set_lights("").await?;
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
    let camera = checked.camera(camera.client(), patches.clone());
    let model = RoomModel {
        problem,
        owners: HashMap::new(),
        start: None,
        hot: Default::default(),
        survey: Some(checked.for_patches(patches)),
    };
    Ok((model, camera))
}
