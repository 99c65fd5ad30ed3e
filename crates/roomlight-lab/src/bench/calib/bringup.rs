//! `roomlight bench calib`'s end-to-end counts (issue 21 item 3): captures from a cold start to
//! the first converged light, and the captures of one projector joining a lit room, both
//! through the one calibration procedure on the simulated room as a rig.

use super::report;
use crate::pipeline::{self, SimRig};
use anyhow::{Context, Result};
use roomlight_calib::procedure::{Event, Placed, Procedure, Settings, Stage, claimed_by};
use roomlight_calib::rig::{Rig, block_on};
use roomlight_sim::scene::{ProjectorKind, ProjectorRole};
use roomlight_sim::{CameraNoise, Room};

/// Captures from a cold start to the first converged light (issue 21: ≤ 120 in the lab): the
/// procedure's bring-up (as `roomlight demo` and a camera agent run it), one capture of the
/// first LED preset's target, and the rounds (momentum, 20 model rounds per capture, the
/// default) until the camera agent's stop rule settles, against the simulator's truth. Also
/// what the model is worth: the true excess of the measured model's optimum.
pub(super) fn cold_start(room: &Room, settings: Settings) -> Result<()> {
    let mut noise = CameraNoise::with_seed(room, 1);
    let bar = indicatif::ProgressBar::hidden();
    let mut lines = Vec::new();
    let cal = pipeline::calibrate_configured(
        room,
        false,
        settings,
        pipeline::Nodes::default(),
        &mut noise,
        &bar,
        |l| lines.push(l),
    )?;
    println!("cold start: calibration in {} captures", cal.captures);
    for l in &lines {
        println!("  {l}");
    }
    println!(
        "  partition of unity, {} projectors that blend: {}",
        cal.blending.len(),
        pipeline::calibrated_partition(room, &cal)?
    );
    let (preset, rounds) = converge(room, &cal, &mut noise)?;
    let total = cal.captures + 1 + rounds.settled;
    println!(
        "cold start to first converged light ({preset}): {total} captures = {} calibration + 1 target + {} rounds (settled; {} to 1% true excess); true excess at the end {:.2}%, of the measured model's optimum {:.2}%",
        cal.captures,
        rounds.settled,
        rounds
            .to_1pct
            .map_or("never".to_string(), |c| c.to_string()),
        100.0 * rounds.final_excess,
        100.0 * rounds.model_excess
    );
    Ok(())
}

/// The rounds after a calibration, against the truth.
struct Rounds {
    /// Captures until the stop rule settled (or the budget of 60).
    settled: usize,
    /// The first capture within 1% of the true optimum.
    to_1pct: Option<usize>,
    /// True excess of the values shown at the end.
    final_excess: f64,
    /// True excess of the measured model's own optimum: the model's accuracy.
    model_excess: f64,
}

/// Measures the first preset's target (one capture) and runs the rounds from the
/// conventional start on the simulated room (the closed loop of `roomlight-core`, plant =
/// the true transport with the camera's noise).
fn converge(
    room: &Room,
    cal: &pipeline::Calibrated,
    noise: &mut CameraNoise,
) -> Result<(String, Rounds)> {
    use roomlight_core::closed_loop::{self, LoopConfig, Plant, PlantConfig};
    use roomlight_core::optimum::optimum;
    let name = room
        .scene()
        .presets
        .first()
        .map_or("no preset".to_string(), |p| p.name.clone());
    let model = pipeline::measure_target(room, cal, 0, noise)?;
    let transport = pipeline::Transport::new(room, &cal.regions, cal.setup())?;
    let truth = pipeline::Truth::new(room, &transport, &model, 0)?;
    let best = optimum(&truth.problem)?;
    let measured_best = optimum(&model.problem)?;
    let config = LoopConfig {
        model_rounds: 20,
        stop_when_settled: true,
        ..LoopConfig::new(roomlight_core::StepRule::Momentum { theta: 1.0 }, 60)
    };
    let mut plant = Plant::new(
        truth.problem.clone(),
        PlantConfig {
            noise_scale: 1.0,
            seed: 1,
            ..PlantConfig::default()
        },
    )?;
    let trace = closed_loop::run(&model.problem, &mut plant, &model.conventional, &config)?;
    let last = trace.last().context("no capture")?;
    Ok((
        name,
        Rounds {
            settled: trace.records.len(),
            to_1pct: trace
                .records
                .iter()
                .find(|r| best.excess(r.true_objective) <= 0.01)
                .map(|r| r.capture),
            final_excess: best.excess(last.true_objective),
            model_excess: best.excess(truth.problem.objective(&measured_best.x)),
        },
    ))
}

/// One projector joining the lit lab (issue 21: ≤ 40 captures): every other luminaire brought
/// up and lit at mid grey, then the last standard luminaire switched on and calibrated hot.
pub(super) fn hot_join(room: &Room, settings: Settings) -> Result<()> {
    use roomlight_calib::rig::Frame as RigFrame;
    let setup = pipeline::setup(room, false)?;
    let joiner = room
        .projectors()
        .iter()
        .enumerate()
        .filter(|(k, p)| {
            p.kind == ProjectorKind::Standard
                && room.scene().projectors[*k].role == ProjectorRole::Luminaire
        })
        .map(|(_, p)| p.name.clone())
        .next_back()
        .context("no standard luminaire")?;
    let others: Vec<&str> = room
        .projectors()
        .iter()
        .map(|p| p.name.as_str())
        .filter(|n| *n != joiner)
        .collect();
    let mut noise = CameraNoise::with_seed(room, 2);
    let mut rig = SimRig::new(room, &mut noise).with_live(&others)?;
    let up = block_on(Procedure::new(&mut rig, settings, |_| {}).bring_up(&setup))?;
    let lit: Vec<(String, RigFrame)> = up
        .placed
        .iter()
        .map(|p| {
            let values = p
                .ids()
                .into_iter()
                .map(|n| (n, roomlight_core::LinearRgb::splat(0.5)))
                .collect();
            (p.projector.id.clone(), RigFrame::Nodes(values))
        })
        .collect();
    let lit: Vec<(&str, RigFrame)> = lit.iter().map(|(id, f)| (id.as_str(), f.clone())).collect();
    block_on(rig.show(&lit))?;
    rig.go_live(&joiner)?;
    let pixels = (room.camera().width * room.camera().height) as usize;
    let claimed = claimed_by(&up.placed, pixels);
    let first = up.placed.iter().map(|p| p.nodes.len() as u32).sum();
    // The stage of every capture, in order.
    let stages = std::sync::Mutex::new(Vec::new());
    let record = |e| {
        if let Event::Captured { stage } = e {
            stages
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .push(stage);
        }
    };
    let joined = block_on(Procedure::new(&mut rig, settings, record).join(
        &setup,
        &joiner,
        Some(&claimed),
        first,
    ))?;
    let stages = stages
        .into_inner()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let mut counts: Vec<(Stage, usize)> = Vec::new();
    for s in stages {
        match counts.iter_mut().find(|(t, _)| *t == s) {
            Some((_, n)) => *n += 1,
            None => counts.push((s, 1)),
        }
    }
    let breakdown: Vec<String> = counts
        .iter()
        .map(|(s, n)| format!("{n} {}", pipeline::stage_name(*s)))
        .collect();
    println!(
        "hot join of {joiner} beside {} lit projectors: {} captures ({}; {} nodes)",
        up.placed.len(),
        joined.captures,
        breakdown.join(", "),
        joined.placed.nodes.len()
    );
    report(
        room,
        &joiner,
        &joined.measured.corr,
        false,
        joined.measured.manifest.tolerance(),
    )?;
    let blended: Vec<&Placed> = up
        .placed
        .iter()
        .chain(std::iter::once(&joined.placed))
        .filter(|p| p.claim.is_some())
        .collect();
    println!(
        "{:<18} partition of unity after the join, {} projectors that blend: {}",
        "",
        blended.len(),
        pipeline::placed_partition(room, &blended)?
    );
    Ok(())
}
