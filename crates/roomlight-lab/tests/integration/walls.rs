//! The walls beyond the charts as measurements (issue 22 item 2): with the wall tiles weighed
//! into the model, the agents' rounds converge to that model's optimum, as they do on the charts
//! alone. The camera measures the room, the model weighs some patches: each measurement must be
//! scaled as its row is (before that was done, the rounds settled 120% above the optimum, worse
//! than their start), and the truth is taken in the same terms.

use crate::support;

use roomlight_lab::pipeline::{self, Model, RunOptions, WALL_WEIGHT};
use roomlight_sim::{CameraNoise, Room};
use std::sync::Arc;

#[test]
fn the_rounds_reach_the_optimum_of_a_model_with_the_walls_weighed_in() {
    let room = Arc::new(Room::build(support::small_scene()).expect("room"));
    let bar = indicatif::ProgressBar::hidden();
    let mut noise = CameraNoise::with_seed(&room, 5);
    let cal = pipeline::calibrate(&room, &mut noise, &bar, |_| {}).expect("calibration");
    let walls = cal.wall_patch_range();
    assert!(walls.len() > 50, "{} wall tiles", walls.len());
    let lit = pipeline::measure_lit(&room, &cal, 0, &mut noise).expect("lit");
    let charts = Model::for_weight(&cal, &lit, 0.0).expect("charts");
    let model = Model::for_weights(&cal, &lit, 0.0, WALL_WEIGHT).expect("walls");
    let weighed = model.patches.iter().filter(|i| walls.contains(i)).count();
    assert!(weighed > 20, "{weighed} wall tiles reached by a node");
    assert_eq!(model.patches.len(), charts.patches.len() + weighed);
    let transport = pipeline::Transport::new(&room, &cal.regions, cal.setup()).expect("transport");
    let truth = pipeline::Truth::new(&room, &transport, &model, 0).expect("truth");
    // The truth asks what the model asks: its optimum is near the model's.
    let best = roomlight_core::optimum::optimum(&model.problem).expect("optimum");
    let true_best = roomlight_core::optimum::optimum(&truth.problem).expect("true optimum");
    let gap = (best.objective - true_best.objective).abs() / true_best.objective;
    assert!(
        gap < 0.2,
        "model {} against truth {}",
        best.objective,
        true_best.objective
    );
    let options = RunOptions {
        max_captures: 12,
        ..RunOptions::default_rule(3)
    };
    let result =
        pipeline::run_agents(&room, &cal, &model, &transport, &truth, options, &bar).expect("run");
    let start = result.trace.first().expect("start").model_excess;
    assert!(
        result.final_excess < 0.05 && result.final_excess < start / 10.0,
        "excess over the walls model's optimum: {start} at the start, {} at the end",
        result.final_excess
    );
    assert!(
        result.true_excess < 0.05,
        "true excess {}",
        result.true_excess
    );
}
