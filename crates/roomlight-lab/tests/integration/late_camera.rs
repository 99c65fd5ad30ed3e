//! A camera that hands over its frames two captures late, its latency not configured: the
//! camera agent refuses the captures that show the room before the nodes' last step
//! (`round::Controller::stale`) and the rounds converge with the default rule. Acting on them
//! instead, the nodes step twice on errors they already answered: with the refusal taken out
//! this run's excess over the model's optimum swung between 1% and 1 379 (2026-12-06), and
//! `bench room --quick --hard`'s stale-2 case ended at 130.

use crate::support;

use roomlight_lab::pipeline::{self, Model, RunOptions};
use roomlight_sim::{CameraNoise, Room};
use std::sync::Arc;

#[test]
fn late_frames_are_refused_and_the_rounds_converge() {
    let room = Arc::new(Room::build(support::small_scene()).expect("room"));
    let bar = indicatif::ProgressBar::hidden();
    let mut noise = CameraNoise::with_seed(&room, 3);
    let cal = pipeline::calibrate(&room, &mut noise, &bar, |_| {}).expect("calibration");
    let lit = pipeline::measure_lit(&room, &cal, 0, &mut noise).expect("lit");
    let model = Model::for_weight(&cal, &lit, 0.0).expect("model");
    let transport = pipeline::Transport::new(&room, &cal.regions, cal.setup()).expect("transport");
    let truth = pipeline::Truth::new(&room, &transport, &model, 0).expect("truth");
    let options = RunOptions {
        max_captures: 12,
        stop_when_settled: false,
        latency: 2,
        discard_stale: false,
        ..RunOptions::default_rule(3)
    };
    let result =
        pipeline::run_agents(&room, &cal, &model, &transport, &truth, options, &bar).expect("run");
    let excess: Vec<(u64, f64)> = result
        .trace
        .iter()
        .map(|p| (p.capture, p.model_excess))
        .collect();
    let start = excess.first().expect("the start").1;
    assert!(
        excess.iter().all(|&(_, e)| e.is_finite() && e <= start),
        "the excess over the model's optimum rose above its start: {excess:?}"
    );
    assert!(
        result.final_excess < 0.01,
        "excess at the end {} (trace {excess:?})",
        result.final_excess
    );
    // Late frames were taken and refused: fewer measured rounds (each followed by its model
    // rounds) than captures. The first capture has no step before it to be late on.
    let per_capture = 1 + options.model_rounds as u64;
    let measured = result.rounds.div_ceil(per_capture);
    assert!(
        measured < result.captures,
        "{} rounds, {measured} measured, in {} captures: nothing refused",
        result.rounds,
        result.captures
    );
    // The status names the latency: two frames.
    assert_eq!(result.late_frames, 2, "late frames in the status");
}
