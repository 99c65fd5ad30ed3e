//! `roomlight calibrate`: a simulated room calibrated in one process, through captures only,
//! written as the files the processes of a rendered room need; or only the survey, for
//! calibration over the wire.

use super::files::{ChartsFile, ModelFile, SurveyFile, load_scene, write_json};
use crate::pipeline;
use anyhow::{Context, Result};
use roomlight_sim::Room;
use roomlight_sim::scene::{ProjectorKind, ProjectorRole};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// What to calibrate and where the files go.
#[derive(Debug, Clone)]
pub struct CalibrateOptions {
    /// `default` (the embedded lab), `small`, or a scene TOML file.
    pub scene: String,
    /// The camera's resolution instead of the scene's.
    pub camera: Option<[u32; 2]>,
    /// The LED preset whose light the projectors reproduce (default: the first).
    pub preset: Option<String>,
    /// Seed of the camera noise.
    pub seed: u64,
    /// Folder for model.json, charts.json and one frame-PROJECTOR.json per luminaire (with
    /// `survey_only`: survey.json).
    pub out: PathBuf,
    /// Write only survey.json and calibrate nothing.
    pub survey_only: bool,
}

/// Calibrates (or surveys) the room of `options` and writes its files.
pub fn calibrate_to_files(options: &CalibrateOptions) -> Result<()> {
    let scene = load_scene(&options.scene, options.camera)?;
    let room = Arc::new(
        Room::build(scene).with_context(|| format!("building the room of {}", options.scene))?,
    );
    std::fs::create_dir_all(&options.out)
        .with_context(|| format!("creating {}", options.out.display()))?;
    if options.survey_only {
        write_survey(&room, &options.out)
    } else {
        write_calibration(&room, options)
    }
}

/// survey.json, and one line per luminaire (`luminaire NAME KIND`) for a node agent to be
/// started for (deploy/local-lab.sh reads these lines).
fn write_survey(room: &Room, out: &Path) -> Result<()> {
    for (p, spec) in room.projectors().iter().zip(&room.scene().projectors) {
        if spec.role == ProjectorRole::Luminaire {
            let kind = match p.kind {
                ProjectorKind::LargeAperture => "large-aperture",
                _ => "standard",
            };
            println!("luminaire {} {kind}", p.name);
        }
    }
    let [camera_width, camera_height] = room.scene().camera.resolution;
    write_json(
        &out.join("survey.json"),
        &SurveyFile {
            camera_width,
            camera_height,
            corners: pipeline::chart_corners(room)?,
            sample: pipeline::sample_config(room),
            target_pixels: room
                .pixels()
                .iter()
                .enumerate()
                .filter(|(_, p)| p.target)
                .map(|(i, _)| i as u32)
                .collect(),
            target_polygons: Vec::new(),
            preset: None,
        },
    )
}

/// model.json, charts.json and the frame files of a room calibrated in this process.
fn write_calibration(room: &Arc<Room>, options: &CalibrateOptions) -> Result<()> {
    let preset = match &options.preset {
        Some(name) => room
            .preset(name)
            .with_context(|| format!("preset {name}"))?,
        None => 0,
    };
    let mut noise = roomlight_sim::CameraNoise::with_seed(room, options.seed);
    let bar = indicatif::ProgressBar::hidden();
    let cal = pipeline::calibrate(room, &mut noise, &bar, |line| println!("{line}"))?;
    let model = pipeline::measure_target(room, &cal, preset, &mut noise)?;
    write_json(
        &options.out.join("model.json"),
        &ModelFile {
            problem: model.problem.clone(),
            owners: cal.owners(room),
            start: Some(model.conventional.clone()),
            patches: None,
            dark_target_weight: None,
        },
    )?;
    write_json(
        &options.out.join("charts.json"),
        &ChartsFile {
            corners: cal.corners.clone(),
            patches: model.patches.clone(),
            sample: pipeline::sample_config(room),
        },
    )?;
    for (k, p) in room.projectors().iter().enumerate() {
        let nodes: Vec<(u32, Vec<(u32, f32)>)> = cal
            .regions
            .iter()
            .enumerate()
            .filter(|(_, r)| r.projector == k)
            .map(|(n, r)| (n as u32, pipeline::sparse_weights(r)))
            .collect();
        if nodes.is_empty() {
            continue;
        }
        let spec = crate::rendered::FrameSpec {
            projector: p.name.clone(),
            width: p.pinhole.width,
            height: p.pinhole.height,
            response: cal.responses[k].clone(),
            nodes,
        };
        write_json(&options.out.join(format!("frame-{}.json", p.name)), &spec)?;
    }
    Ok(())
}
