//! `roomlight bench core`: every rule from the conventional start on synthetic rooms; captures
//! to 1% and 0.1% excess over the exact optimum, final ΔE00, and compute cost. Timings are
//! printed and compared, never asserted.

use anyhow::{Context, Result};
use comfy_table::{Table, presets::UTF8_FULL_CONDENSED};
use roomlight_core::aggregator::ErrorAggregator;
use roomlight_core::closed_loop::{self, LoopConfig, Plant, PlantConfig};
use roomlight_core::conventional::conventional_start;
use roomlight_core::metrics::patch_delta_e;
use roomlight_core::optimum::{global_step, optimum};
use roomlight_core::rules::NodeState;
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use roomlight_core::{LinearRgb, Problem, StepRule};
use serde::Serialize;
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

/// One row of the table and of `--json`.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub case: String,
    pub rule: String,
    pub captures_to_1pct: Option<usize>,
    pub captures_to_0_1pct: Option<usize>,
    pub final_excess: f64,
    pub mean_de00: f64,
    pub us_per_node_update: f64,
    pub model_rounds: usize,
    pub captures: usize,
}

/// The rules compared, by name.
pub fn rules(problem: &Problem, budget: usize) -> Vec<(&'static str, LoopConfig)> {
    let with = |rule, model_rounds| LoopConfig {
        model_rounds,
        ..LoopConfig::new(rule, budget)
    };
    vec![
        ("paper", with(StepRule::paper(), 0)),
        (
            "global-oracle",
            with(
                StepRule::Fixed {
                    epsilon: global_step(problem),
                },
                0,
            ),
        ),
        ("safe", with(StepRule::Safe { theta: 1.0 }, 0)),
        ("momentum", with(StepRule::Momentum { theta: 1.0 }, 0)),
        ("model-5", with(StepRule::Momentum { theta: 1.0 }, 5)),
        ("model-20", with(StepRule::Momentum { theta: 1.0 }, 20)),
    ]
}

/// Median wall time per node update, in µs, over `repeats` timed rounds of every node.
pub fn us_per_node_update(problem: &Problem, rule: StepRule, start: &[LinearRgb]) -> Result<f64> {
    let errors = problem.errors(start);
    let mut nodes: Vec<NodeState> = closed_loop::build_nodes(problem, rule, start)?;
    let local: Vec<Vec<LinearRgb>> = nodes
        .iter()
        .map(|node| {
            node.column()
                .support()
                .iter()
                .map(|&i| errors[i as usize])
                .collect()
        })
        .collect();
    let mut samples = Vec::new();
    for _ in 0..9 {
        let t0 = Instant::now();
        let mut updates = 0usize;
        while t0.elapsed().as_secs_f64() < 0.01 {
            for (node, e) in nodes.iter_mut().zip(&local) {
                black_box(node.update(black_box(e), false)?);
                updates += 1;
            }
        }
        samples.push(t0.elapsed().as_secs_f64() * 1e6 / updates as f64);
    }
    Ok(median(&mut samples))
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Wall time and memory of one full distributed round (every node gathers, updates and
/// contributes), as the ms median of repeated rounds and how far the resident set's peak rose
/// while the node states were built and used (see `bench::memory`).
fn full_round(problem: &Problem, start: &[LinearRgb]) -> Result<(f64, Option<f64>)> {
    let errors = problem.errors(start);
    let (samples, peak_mb) = super::memory::peak_growth(|| rounds(problem, start, &errors));
    let mut samples = samples?;
    Ok((median(&mut samples), peak_mb))
}

/// Fifteen distributed rounds from `start`, each timed in ms.
fn rounds(problem: &Problem, start: &[LinearRgb], errors: &[LinearRgb]) -> Result<Vec<f64>> {
    let mut nodes: Vec<NodeState> =
        closed_loop::build_nodes(problem, StepRule::Momentum { theta: 1.0 }, start)?;
    let mut aggregator = ErrorAggregator::new(problem.patches());
    aggregator.measured(errors.to_vec())?;
    let active = vec![true; nodes.len()];
    let mut samples = Vec::new();
    for _ in 0..15 {
        let t0 = Instant::now();
        closed_loop::distributed_round(&mut nodes, &active, errors, false, &mut aggregator)?;
        samples.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    Ok(samples)
}

/// One synthetic room of the benchmark.
struct Case {
    name: String,
    config: SyntheticConfig,
    noise_scale: f64,
}

impl Case {
    fn plain(nodes: usize, seed: u64) -> Self {
        Self {
            name: format!("synthetic-{nodes}"),
            config: SyntheticConfig::new(nodes, seed),
            noise_scale: 0.0,
        }
    }
}

/// Runs the core benchmark and prints the table.
pub fn core(quick: bool, json: Option<&Path>, seed: u64) -> Result<()> {
    let budget = if quick { 150 } else { 400 };
    let mut rows = Vec::new();
    for case in &cases(quick, seed) {
        rows.extend(bench_case(case, budget, seed)?);
    }
    print_table(&rows);
    if let Some(path) = json {
        std::fs::write(path, serde_json::to_string_pretty(&rows)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// The synthetic rooms of 10, 100 and 1000 nodes (up to 100 with `quick`), and without
/// `quick` two harder rooms of 100.
fn cases(quick: bool, seed: u64) -> Vec<Case> {
    let mut cases: Vec<Case> = [10, 100, 1000]
        .into_iter()
        .filter(|&n| !quick || n <= 100)
        .map(|n| Case::plain(n, seed))
        .collect();
    if !quick {
        // A very reflective room (albedo ≈ 0.9: three times the inter-reflection) with many dim
        // projectors, and the ordinary room seen by a camera with its real noise.
        let mut reflective = Case::plain(100, seed);
        reflective.name = "reflective-100".into();
        reflective.config.interreflection = 3.0;
        reflective.config.dim_share = 0.3;
        cases.push(reflective);
        let mut noisy = Case::plain(100, seed);
        noisy.name = "noisy-100".into();
        noisy.noise_scale = 1.0;
        cases.push(noisy);
    }
    cases
}

/// Every rule on one room from the conventional start: prints the room's line and the time of
/// one distributed round, returns a row per rule.
fn bench_case(case: &Case, budget: usize, seed: u64) -> Result<Vec<Row>> {
    let mut rows = Vec::new();
    let nodes = case.config.nodes;
    let room = synthetic_room(&case.config)
        .with_context(|| format!("building the synthetic room {}", case.name))?;
    let problem = &room.problem;
    let t0 = Instant::now();
    let best = optimum(problem).with_context(|| format!("optimum of {nodes} nodes"))?;
    let t_opt = t0.elapsed().as_secs_f64();
    let start = conventional_start(problem, &room.charts, LinearRgb::splat(0.5))?;
    let kept: usize = problem.columns().iter().map(|c| c.len()).sum();
    println!(
        "{}: {nodes} nodes, {} patches: {kept} attenuation entries kept ({:.2}% of dense), G* = {:.4e} (KKT residual {:.1e}, {:.2} s), conventional excess {:.3}",
        case.name,
        problem.patches(),
        100.0 * kept as f64 / (nodes * problem.patches()) as f64,
        best.objective,
        best.kkt_residual,
        t_opt,
        best.excess(problem.objective(&start)),
    );
    for (name, mut config) in rules(problem, budget) {
        config.stop_at_true_objective =
            Some(best.objective + 1e-6 * best.objective.max(1e-9 * best.objective_black));
        let plant_config = PlantConfig {
            noise_scale: case.noise_scale,
            seed,
            ..PlantConfig::default()
        };
        let mut plant = Plant::new(problem.clone(), plant_config)?;
        let trace = closed_loop::run(problem, &mut plant, &start, &config)?;
        let last = trace.last().context("no capture recorded")?;
        let to = |frac: f64| {
            trace
                .records
                .iter()
                .find(|r| best.excess(r.true_objective) <= frac)
                .map(|r| r.capture)
        };
        let de = patch_delta_e(
            problem.target(),
            &plant.true_response(&trace.shown, last.capture),
        )?;
        rows.push(Row {
            case: case.name.clone(),
            rule: name.to_string(),
            captures_to_1pct: to(0.01),
            captures_to_0_1pct: to(0.001),
            final_excess: best.excess(last.true_objective),
            mean_de00: de.mean,
            us_per_node_update: us_per_node_update(problem, config.rule, &start)?,
            model_rounds: last.model_rounds,
            captures: last.capture,
        });
    }
    let (round_ms, round_mb) = full_round(problem, &start)?;
    let support: f64 = kept as f64 / nodes as f64;
    println!(
        "  one distributed round of {nodes} nodes (mean support {support:.0} patches): {round_ms:.3} ms, peak resident growth {}",
        super::memory::mb(round_mb)
    );
    Ok(rows)
}

fn print_table(rows: &[Row]) {
    let mut table = Table::new();
    table.load_preset(UTF8_FULL_CONDENSED).set_header(vec![
        "case",
        "rule",
        "captures to 1%",
        "captures to 0.1%",
        "final excess",
        "mean ΔE00",
        "µs / node update",
        "captures run",
        "model rounds",
    ]);
    let opt = |v: Option<usize>| v.map_or("never".to_string(), |c| c.to_string());
    for r in rows {
        table.add_row(vec![
            r.case.clone(),
            r.rule.clone(),
            opt(r.captures_to_1pct),
            opt(r.captures_to_0_1pct),
            format!("{:.2e}", r.final_excess),
            format!("{:.3}", r.mean_de00),
            format!("{:.3}", r.us_per_node_update),
            r.captures.to_string(),
            r.model_rounds.to_string(),
        ]);
    }
    super::width::fit(&mut table);
    println!("{table}");
}
