//! The files the processes of a simulated installation hand each other, read and checked, and
//! the scenes they are built from.

use anyhow::{Context, Result, bail};
use roomlight_calib::charts::{ChartCorners, SampleConfig};
use roomlight_calib::image_io::MAX_LOAD_SIDE;
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
    /// Written with `patches`: the weight its target patches' rows were scaled with (absent:
    /// 0, no target patches).
    #[serde(default)]
    pub dark_target_weight: Option<f64>,
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
    /// The target as the console drew it (polygons in camera pixels); `target_pixels` is what
    /// counts.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub target_polygons: Vec<Vec<[f64; 2]>>,
    /// The LED preset to reproduce, as the console picked it (the camera config's `preset`
    /// comes first).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub preset: Option<String>,
}

/// The most charts a survey may name (a room has a few dozen).
pub const MAX_CHARTS: usize = 1024;

impl SurveyFile {
    /// A survey file's text, parsed and checked before anything is allocated from it: the
    /// camera's size (1 to [`MAX_LOAD_SIDE`] a side, as for captures), the target's pixels
    /// inside it and increasing, charts named, distinct, at most [`MAX_CHARTS`], their corners
    /// finite and inside the image, the sampling's levels finite and in range. `source` names
    /// the file in every error.
    pub fn parse(text: &str, source: &Path) -> Result<Self> {
        let at = source.display();
        let survey: Self =
            serde_json::from_str(text).with_context(|| format!("{at}: not a survey file"))?;
        let (w, h) = (survey.camera_width, survey.camera_height);
        if !(1..=MAX_LOAD_SIDE).contains(&w) || !(1..=MAX_LOAD_SIDE).contains(&h) {
            bail!(
                "{at}: camera_width × camera_height {w}×{h}, expected 1 to {MAX_LOAD_SIDE} a side"
            );
        }
        let pixels = u64::from(w) * u64::from(h);
        if let Some(pair) = survey.target_pixels.windows(2).find(|p| p[0] >= p[1]) {
            bail!(
                "{at}: target_pixels not increasing ({} then {})",
                pair[0],
                pair[1]
            );
        }
        if let Some(&bad) = survey
            .target_pixels
            .last()
            .filter(|&&i| u64::from(i) >= pixels)
        {
            bail!("{at}: target pixel {bad} outside the {w}×{h} camera");
        }
        if survey.corners.len() > MAX_CHARTS {
            bail!(
                "{at}: {} charts, at most {MAX_CHARTS}",
                survey.corners.len()
            );
        }
        let mut names = std::collections::HashSet::new();
        for (i, chart) in survey.corners.iter().enumerate() {
            if chart.name.is_empty() || !names.insert(chart.name.as_str()) {
                bail!(
                    "{at}: corners[{i}]: a chart needs a name of its own, got {:?}",
                    chart.name
                );
            }
            let inside = |&[x, y]: &[f64; 2]| {
                x.is_finite()
                    && y.is_finite()
                    && (0.0..=f64::from(w)).contains(&x)
                    && (0.0..=f64::from(h)).contains(&y)
            };
            if let Some(c) = chart.corners.iter().find(|c| !inside(c)) {
                bail!(
                    "{at}: chart {:?}: corner {c:?} outside the {w}×{h} image",
                    chart.name
                );
            }
        }
        let s = &survey.sample;
        let level = |v: f64| v.is_finite() && v >= 0.0;
        if !(s.saturation > 0.0 && s.saturation <= 1.0) {
            bail!(
                "{at}: sample.saturation {}, expected in (0, 1]",
                s.saturation
            );
        }
        for (field, v) in [
            ("read_noise", f64::from(s.read_noise)),
            ("shot_noise", f64::from(s.shot_noise)),
            ("max_nonuniformity", s.max_nonuniformity),
        ] {
            if !level(v) {
                bail!("{at}: sample.{field} {v}, expected a finite value ≥ 0");
            }
        }
        Ok(survey)
    }

    /// The target as a row-major camera mask (its pixels were checked by [`Self::parse`]).
    pub fn target_mask(&self) -> Vec<bool> {
        let mut mask = vec![false; self.camera_width as usize * self.camera_height as usize];
        for &i in &self.target_pixels {
            if let Some(m) = mask.get_mut(i as usize) {
                *m = true;
            }
        }
        mask
    }
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
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    ModelFile::parse(&text, path)
}

/// A survey file, checked ([`SurveyFile::parse`]).
pub fn load_survey(path: &Path) -> Result<SurveyFile> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    SurveyFile::parse(&text, path)
}

impl ModelFile {
    /// A model file's text, parsed and checked: the problem revalidated (finite, sizes that
    /// agree), every owned node inside it, starts one per node within [0, 1], patches one per
    /// model patch. `source` names the file in every error.
    pub fn parse(text: &str, source: &Path) -> Result<Self> {
        let at = source.display();
        let model: Self =
            serde_json::from_str(text).with_context(|| format!("{at}: not a room model"))?;
        let problem = model
            .problem
            .revalidate()
            .with_context(|| format!("{at}: invalid model"))?;
        for (p, nodes) in &model.owners {
            if let Some(n) = nodes.iter().find(|&&n| n as usize >= problem.nodes()) {
                bail!(
                    "{at}: projector {p:?} owns node {n}, the model has {} nodes",
                    problem.nodes()
                );
            }
        }
        if let Some(start) = &model.start {
            if start.len() != problem.nodes() {
                bail!(
                    "{at}: start has {} values, the model {} nodes",
                    start.len(),
                    problem.nodes()
                );
            }
            if let Some(n) = start.iter().position(|v| {
                v.0.iter()
                    .any(|c| !(c.is_finite() && (0.0..=1.0).contains(c)))
            }) {
                bail!("{at}: start[{n}] {:?}, expected values in [0, 1]", start[n]);
            }
        }
        if let Some(patches) = &model.patches
            && patches.len() != problem.patches()
        {
            bail!(
                "{at}: {} patches listed, the model has {}",
                patches.len(),
                problem.patches()
            );
        }
        Ok(Self { problem, ..model })
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// What the console saves is a survey the camera agent reads: its target pixels are the
    /// polygon's, and the preset the console picked comes back.
    #[test]
    fn the_consoles_survey_is_read_by_the_camera_agent() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("survey.json");
        let first = SurveyFile {
            camera_width: 64,
            camera_height: 48,
            corners: Vec::new(),
            sample: SampleConfig::default(),
            target_pixels: vec![1, 2],
            target_polygons: Vec::new(),
            preset: None,
        };
        std::fs::write(&path, serde_json::to_string(&first).expect("JSON")).expect("write");
        let (_, mut survey) = roomlight_console::survey::read(&path).expect("the console reads it");
        assert_eq!(survey.target_pixels, 2);
        survey.charts.push(ChartCorners {
            name: "desk".into(),
            corners: [[2.0, 2.0], [20.0, 2.0], [20.0, 14.0], [2.0, 14.0]],
        });
        survey.target = vec![vec![[30.0, 10.0], [40.0, 10.0], [40.0, 20.0], [30.0, 20.0]]];
        survey.preset = Some("warm".into());
        roomlight_console::survey::validate(&survey, &survey.clone(), &[]).expect("valid");
        roomlight_console::survey::write(&path, &survey).expect("saved");
        let read = load_survey(&path).expect("the camera agent reads it");
        assert_eq!(read.preset.as_deref(), Some("warm"));
        assert_eq!(read.corners.len(), 1);
        let mask = read.target_mask();
        let inside: Vec<usize> = (0..mask.len()).filter(|&i| mask[i]).collect();
        let expected: Vec<usize> = (10..20)
            .flat_map(|y| (30..40).map(move |x| y * 64 + x))
            .collect();
        assert_eq!(inside, expected);
    }
}
