//! The hard cases of DESIGN §9 that exist at the level of the core, on small synthetic rooms:
//! every run stays finite and in bounds, and converges where the theory says it does.

use roomlight_core::closed_loop::{self, LoopConfig, Plant, PlantConfig, Trace};
use roomlight_core::conventional::conventional_start;
use roomlight_core::optimum::{Optimum, optimum};
use roomlight_core::synthetic::{SyntheticConfig, SyntheticRoom, synthetic_room};
use roomlight_core::{AttenuationColumn, LinearRgb, Problem, StepRule};

fn room(nodes: usize, seed: u64) -> SyntheticRoom {
    synthetic_room(&SyntheticConfig::new(nodes, seed)).expect("synthetic room")
}

fn start(room: &SyntheticRoom) -> Vec<LinearRgb> {
    conventional_start(&room.problem, &room.charts, LinearRgb::splat(0.5)).expect("start")
}

fn run(
    model: &Problem,
    truth: &Problem,
    plant: PlantConfig,
    x0: &[LinearRgb],
    config: LoopConfig,
) -> (Trace, Plant) {
    let mut plant = Plant::new(truth.clone(), plant).expect("plant");
    let trace = closed_loop::run(model, &mut plant, x0, &config).expect("loop");
    for r in &trace.records {
        assert!(
            r.true_objective.is_finite() && r.measured_objective.is_finite(),
            "non-finite G"
        );
    }
    for x in &trace.shown {
        assert!(
            x.is_finite() && x.min_channel() >= 0.0 && x.max_abs() <= 1.0,
            "out of bounds: {x:?}"
        );
    }
    (trace, plant)
}

fn final_excess(best: &Optimum, trace: &Trace) -> f64 {
    best.excess(trace.last().expect("records").true_objective)
}

/// Errors one and two rounds old: the safe step with the θ the delay rule allows
/// (θ < 2 sin(π/(2(2τ+1))): 1.0 for τ = 1, 0.618 for τ = 2) converges; θ = 1 with τ = 2
/// violates the rule and does not.
#[test]
fn stale_errors_converge_with_the_allowed_theta() {
    let room = room(30, 3);
    let p = &room.problem;
    let best = optimum(p).expect("optimum");
    let x0 = start(&room);
    for (delay, theta, limit) in [(1, 0.7, 1e-3), (2, 0.433, 1e-2)] {
        let rule = StepRule::safe_for_delay(delay);
        let StepRule::Safe { theta: chosen } = rule else {
            panic!("safe_for_delay gave {rule:?}");
        };
        assert!((chosen - theta).abs() < 1e-3, "τ = {delay}: θ {chosen}");
        let config = LoopConfig {
            delay,
            ..LoopConfig::new(rule, 100)
        };
        let (trace, _) = run(p, p, PlantConfig::default(), &x0, config);
        let excess = final_excess(&best, &trace);
        assert!(excess < limit, "τ = {delay}, θ = {theta}: excess {excess}");
    }
    let config = LoopConfig {
        delay: 2,
        ..LoopConfig::new(StepRule::Safe { theta: 1.0 }, 100)
    };
    let (trace, _) = run(p, p, PlantConfig::default(), &x0, config);
    assert!(
        final_excess(&best, &trace) > 1.0,
        "θ = 1 with τ = 2 was expected to oscillate"
    );
}

/// Projectors with an uncorrected gamma of 2.2: the set of reachable light is the same, so the
/// loop must still reach the linear optimum; the safe step does, momentum and model rounds too.
#[test]
fn uncorrected_gamma_still_reaches_the_optimum() {
    let room = room(30, 3);
    let p = &room.problem;
    let best = optimum(p).expect("optimum");
    let x0 = start(&room);
    let plant = PlantConfig {
        gamma: 2.2,
        ..PlantConfig::default()
    };
    for (rule, model_rounds, limit) in [
        (StepRule::Safe { theta: 1.0 }, 0, 1e-6),
        (StepRule::Momentum { theta: 1.0 }, 0, 1e-4),
        (StepRule::Momentum { theta: 1.0 }, 5, 1e-4),
    ] {
        let config = LoopConfig {
            model_rounds,
            ..LoopConfig::new(rule, 60)
        };
        let (trace, _) = run(p, p, plant.clone(), &x0, config);
        let first = best.excess(trace.records[0].true_objective);
        let excess = final_excess(&best, &trace);
        assert!(
            first > 1.0 && excess < limit,
            "{rule:?} K={model_rounds}: excess {first} → {excess}"
        );
    }
}

/// Heavy camera noise (ten times the patch noise) and a camera that saturates: no divergence,
/// the error falls from the start and stays at the noise floor.
#[test]
fn heavy_noise_and_saturation_stay_bounded() {
    let room = room(30, 3);
    let p = &room.problem;
    let best = optimum(p).expect("optimum");
    let x0 = start(&room);
    let brightest = p.target().iter().map(|t| t.max_abs()).fold(0.0, f64::max);
    let plant = PlantConfig {
        noise_scale: 10.0,
        seed: 7,
        saturation: Some(0.8 * brightest),
        ..PlantConfig::default()
    };
    for (rule, model_rounds) in [
        (StepRule::Safe { theta: 1.0 }, 0),
        (StepRule::Momentum { theta: 1.0 }, 0),
        (StepRule::Momentum { theta: 1.0 }, 5),
    ] {
        let config = LoopConfig {
            model_rounds,
            ..LoopConfig::new(rule, 80)
        };
        let (trace, _) = run(p, p, plant.clone(), &x0, config);
        let first = best.excess(trace.records[0].true_objective);
        let worst_late = trace.records[20..]
            .iter()
            .map(|r| best.excess(r.true_objective))
            .fold(0.0, f64::max);
        assert!(
            worst_late < 0.25 * first && worst_late < 1.0,
            "{rule:?} K={model_rounds}: start {first}, late worst {worst_late}"
        );
    }
}

/// A node leaves at capture 10: its light vanishes from the errors and the others make up for
/// it, reaching the optimum of the room without it.
#[test]
fn a_node_leaving_mid_run_is_corrected_by_the_others() {
    let room = room(30, 3);
    let p = &room.problem;
    let x0 = start(&room);
    let gone = 12;
    let plant = PlantConfig {
        departures: vec![(gone, 10)],
        ..PlantConfig::default()
    };
    for (rule, model_rounds) in [
        (StepRule::Safe { theta: 1.0 }, 0),
        (StepRule::Momentum { theta: 1.0 }, 0),
        (StepRule::Momentum { theta: 1.0 }, 5),
    ] {
        let config = LoopConfig {
            model_rounds,
            ..LoopConfig::new(rule, 60)
        };
        let (trace, plant) = run(p, p, plant.clone(), &x0, config);
        let after = optimum(&plant.truth_at(60)).expect("optimum without the node");
        let before = optimum(p).expect("optimum");
        assert!(after.objective > before.objective, "the node mattered");
        let jump = after.excess(trace.records[9].true_objective);
        let excess = final_excess(&after, &trace);
        assert!(
            jump > 0.01 && excess < 1e-3,
            "{rule:?} K={model_rounds}: after leaving {jump}, at the end {excess}"
        );
    }
}

/// Model rounds are iterative learning control: with a reachable target the loop reaches it even
/// when the nodes' measured attenuation is off by up to ±25% per node and channel.
#[test]
fn model_rounds_reach_a_reachable_target_with_a_wrong_model() {
    let room = room(30, 5);
    let truth = &room.problem;
    // A target the projectors can give exactly: the light of an interior x_true.
    let x_true: Vec<LinearRgb> = (0..truth.nodes())
        .map(|n| LinearRgb([0.3 + 0.013 * n as f64, 0.5, 0.7 - 0.01 * n as f64]))
        .collect();
    let truth = truth.with_target(truth.response(&x_true)).expect("target");
    let columns = truth
        .columns()
        .iter()
        .enumerate()
        .map(|(n, c)| {
            let k = LinearRgb([0.75 + 0.5 * ((n * 7) % 11) as f64 / 10.0, 1.2, 0.8]);
            AttenuationColumn::new(
                c.support().to_vec(),
                c.values().iter().map(|v| v.hadamard(k)).collect(),
            )
            .expect("column")
        })
        .collect();
    let model = Problem::new(
        columns,
        truth.black().to_vec(),
        truth.target().to_vec(),
        truth.noise().to_vec(),
    )
    .expect("model");
    let x0 = vec![LinearRgb::splat(0.5); truth.nodes()];
    let scale = truth.objective(&x0);
    for (rule, model_rounds) in [
        (StepRule::Safe { theta: 1.0 }, 5),
        (StepRule::Momentum { theta: 1.0 }, 5),
        (StepRule::Safe { theta: 1.0 }, 0),
    ] {
        // A noiseless camera: averaging captures has no noise to remove, and it would lag
        // behind the ±25% model's predictions in the last digits (1.9e-7 of G(x0) after 40
        // captures instead of below 1e-8).
        let config = LoopConfig {
            model_rounds,
            average: 1,
            ..LoopConfig::new(rule, 40)
        };
        let (trace, _) = run(&model, &truth, PlantConfig::default(), &x0, config);
        let last = trace.last().expect("records").true_objective;
        assert!(
            last < 1e-8 * scale,
            "{rule:?} K={model_rounds}: G {last} of {scale}"
        );
    }
}

/// A very reflective room (albedo 0.9: three times the inter-reflection), many dim projectors,
/// a node with no chart of its own: everything stays finite and the rules converge.
#[test]
fn reflective_room_dim_projectors_and_a_node_without_a_chart() {
    let mut config = SyntheticConfig::new(36, 11);
    config.interreflection = 3.0;
    config.dim_share = 0.4;
    let mut room = synthetic_room(&config).expect("room");
    room.charts[4].clear(); // node 4 has no chart in view: conventional start falls back
    let p = &room.problem;
    let best = optimum(p).expect("optimum");
    let x0 = start(&room);
    assert_eq!(x0[4], LinearRgb::splat(0.5));
    for (rule, model_rounds, budget) in [
        (StepRule::paper(), 0, 400),
        (StepRule::Safe { theta: 1.0 }, 0, 200),
        (StepRule::Momentum { theta: 1.0 }, 0, 100),
        (StepRule::Momentum { theta: 1.0 }, 5, 30),
    ] {
        let config = LoopConfig {
            model_rounds,
            ..LoopConfig::new(rule, budget)
        };
        let (trace, _) = run(p, p, PlantConfig::default(), &x0, config);
        let excess = final_excess(&best, &trace);
        assert!(excess < 1e-3, "{rule:?} K={model_rounds}: excess {excess}");
    }
}

/// The stop rules of DESIGN §3.6 end a converged run by themselves, well inside the budget: on
/// a noiseless camera when the steps fall below half a code step or `G` stops changing, and on a
/// noisy camera (where noise keeps every node twitching) when `G` changes by less than its noise.
#[test]
fn the_loop_stops_by_itself_once_converged() {
    let room = room(30, 3);
    let p = &room.problem;
    let best = optimum(p).expect("optimum");
    for (noise_scale, rule, model_rounds) in [
        (0.0, StepRule::Momentum { theta: 1.0 }, 0),
        (0.0, StepRule::Safe { theta: 1.0 }, 0),
        (1.0, StepRule::Momentum { theta: 1.0 }, 5),
        (1.0, StepRule::Safe { theta: 1.0 }, 0),
    ] {
        let config = LoopConfig {
            model_rounds,
            stop_when_settled: true,
            ..LoopConfig::new(rule, 500)
        };
        let plant = PlantConfig {
            noise_scale,
            seed: 3,
            ..PlantConfig::default()
        };
        let (trace, _) = run(p, p, plant, &start(&room), config);
        assert_ne!(
            trace.stop,
            closed_loop::StopReason::Budget,
            "{rule:?}, noise {noise_scale}"
        );
        assert!(
            trace.records.len() < 60,
            "{rule:?}, noise {noise_scale}: {} captures",
            trace.records.len()
        );
        let excess = final_excess(&best, &trace);
        assert!(
            excess < 5e-3,
            "{rule:?}, noise {noise_scale}: excess {excess}"
        );
    }
}
