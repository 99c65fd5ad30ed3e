//! What the measured model could reach over the whole room (issue 22, item 2), beside what
//! the rounds reached: the model's exact optimum for a preset, rendered noiselessly and
//! compared with the LEDs pixel by pixel ([`crate::whole_room`]), once for the model over the
//! charts alone (what the rounds minimise by default) and once with the walls beyond the charts
//! weighed in ([`crate::pipeline::WALL_WEIGHT`]). The pair is the trade-off the walls buy:
//! whole-room ΔE00 and seams against ΔE00 at the charts.

use crate::pipeline::{Calibrated, FrameBuilder, Model};
use crate::whole_room::{Reach, ReachMap, WholeRoom, delta_e_map, white_luminance};
use anyhow::{Context, Result};
use roomlight_calib::charts::PatchSample;
use roomlight_core::LinearRgb;
use roomlight_sim::{Capture, Frame, Room};

/// The whole-room figures of node values `x` against `reference` (the room rendered
/// noiselessly under the LEDs): the room rendered with `x` (through the measured responses),
/// compared pixel by pixel as the report's maps are.
pub fn of_values(
    room: &Room,
    cal: &Calibrated,
    reach: &ReachMap,
    reference: &Capture,
    x: &[LinearRgb],
) -> Result<WholeRoom> {
    let frames = FrameBuilder::new(room, &cal.regions, cal.responses.clone())?;
    let lit = room.render(&frames.frames(x), None)?;
    let surface: Vec<bool> = reach.reach.iter().map(|r| *r != Reach::NoSurface).collect();
    let white = white_luminance(reference, &surface)?;
    WholeRoom::measure(&delta_e_map(reference, &lit, white)?, reach, white)
}

/// One model's optimum, seen over the whole room and at the charts.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Best {
    /// Weight of each wall patch (0: the charts alone).
    pub wall_weight: f64,
    /// The model's patches (charts, and the walls its nodes reach).
    pub patches: usize,
    pub whole_room_de00_mean: f64,
    pub whole_room_de00_p95: f64,
    /// The seam metric ([`crate::whole_room::Seam::excess_de00`]), if there are overlaps.
    pub seam_excess_de00: Option<f64>,
    /// Mean ΔE00 over the chart patches, as the model predicts them at its optimum.
    pub chart_de00_mean: f64,
}

/// The measured model's optimum for the LED capture `lit`, with the walls weighed
/// `wall_weight`, against `reference` (the LEDs' noiseless render).
pub fn best(
    room: &Room,
    cal: &Calibrated,
    reach: &ReachMap,
    reference: &Capture,
    lit: &[PatchSample],
    wall_weight: f64,
) -> Result<Best> {
    let model = Model::for_weights(cal, lit, 0.0, wall_weight)?;
    let optimum = roomlight_core::optimum::optimum(&model.problem)
        .with_context(|| format!("the model's optimum with walls weighed {wall_weight}"))?;
    let whole = of_values(room, cal, reach, reference, &optimum.x)?;
    // Chart patches carry scale 1: their modelled values are r − e.
    let charts =
        cal.corners.len() * roomlight_calib::charts::COLUMNS * roomlight_calib::charts::ROWS;
    let errors = model.problem.errors(&optimum.x);
    let (target, modelled): (Vec<LinearRgb>, Vec<LinearRgb>) = model
        .patches
        .iter()
        .enumerate()
        .filter(|(_, i)| **i < charts)
        .map(|(k, _)| {
            (
                model.problem.target()[k],
                model.problem.target()[k] - errors[k],
            )
        })
        .unzip();
    let chart_de00 = roomlight_core::metrics::patch_delta_e(&target, &modelled)?;
    Ok(Best {
        wall_weight,
        patches: model.patches.len(),
        whole_room_de00_mean: whole.de00_mean,
        whole_room_de00_p95: whole.de00_p95,
        seam_excess_de00: whole.seam.map(|s| s.excess_de00),
        chart_de00_mean: chart_de00.mean,
    })
}

/// The pair the report shows: the charts alone, and with the walls at
/// [`crate::pipeline::WALL_WEIGHT`].
pub fn pair(
    room: &Room,
    cal: &Calibrated,
    reach: &ReachMap,
    preset: usize,
    lit: &[PatchSample],
) -> Result<[Best; 2]> {
    let dark = vec![Frame::Black; room.projectors().len()];
    let reference = room.render(&dark, Some(preset))?;
    Ok([
        best(room, cal, reach, &reference, lit, 0.0)?,
        best(
            room,
            cal,
            reach,
            &reference,
            lit,
            crate::pipeline::WALL_WEIGHT,
        )?,
    ])
}
