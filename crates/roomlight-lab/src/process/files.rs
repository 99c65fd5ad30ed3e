//! The files the processes of a simulated installation hand each other, read and checked, and
//! the scenes they are built from.

use anyhow::{Context, Result, bail};
use roomlight_calib::charts::{ChartCorners, SampleConfig};
use roomlight_core::{LinearRgb, Problem};
use roomlight_sim::scene::Scene;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::Path;

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
    pub corners: Vec<ChartCorners>,
    /// Room patch index of each model patch.
    pub patches: Vec<usize>,
    pub sample: SampleConfig,
}

/// What a camera agent needs to calibrate projectors over the wire (DESIGN §4): the charts'
/// corners in the camera image (clicked once in a real room), how to sample them, and the
/// target's camera pixels.
#[derive(Debug, Serialize, Deserialize)]
pub struct SurveyFile {
    pub camera_width: u32,
    pub camera_height: u32,
    pub corners: Vec<ChartCorners>,
    pub sample: SampleConfig,
    /// Row-major camera pixels of the target, increasing.
    pub target_pixels: Vec<u32>,
}

pub(super) fn read_json<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{}: not {what}", path.display()))
}

/// Writes `value` as JSON to `path` (through a temporary file, so a reader never sees half).
pub(super) fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, serde_json::to_string(value)?)
        .with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))?;
    println!("wrote {}", path.display());
    Ok(())
}

/// A scene by name (`default` or `lab`: the embedded lab; `small`) or TOML file, with the
/// camera's resolution optionally replaced.
pub fn load_scene(which: &str, camera: Option<[u32; 2]>) -> Result<Scene> {
    let mut scene = match which {
        "default" | "lab" => roomlight_sim::scenes::lab()?,
        "small" => roomlight_sim::scenes::small()?,
        path => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading the scene {path}"))?;
            Scene::from_toml(&text, path)?
        }
    };
    if let Some(resolution) = camera {
        scene.camera.resolution = resolution;
    }
    Ok(scene)
}

/// A calibrated model file, checked.
pub fn load_model(path: &Path) -> Result<ModelFile> {
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

/// A model file's nodes, projectors, patches (and those left out), G* and G with every node
/// black, in one line.
pub fn optimum_summary(path: &Path) -> Result<String> {
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
    Ok(format!(
        "{}: {} nodes of {} projectors, {} patches ({left_out} left out), G* {:.6e}, G at black {:.6e}",
        path.display(),
        p.nodes(),
        model.owners.len(),
        p.patches(),
        best.objective,
        best.objective_black
    ))
}
