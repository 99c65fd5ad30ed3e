//! `roomlight bench` and `roomlight bench room`: speed against error, through the real agents on
//! loopback from the conventional start, for every rule — on the simulated default room (each
//! LED preset), on the hard cases of DESIGN §9, and on a synthetic room of a thousand nodes.
//! Captures to 1% and 0.1% excess over the model's `G*`, final excess and ΔE00, and where the
//! time goes: the simulated camera, the node updates (timed separately on the same problem),
//! the messages (the rest). Every figure is the median of repeated runs (camera noise seeds)
//! with its range. Timings are printed and compared, never asserted.

use crate::pipeline::{self, Churn, RunOptions, RunResult};
use anyhow::{Context, Result, bail};
use comfy_table::{Table, presets::UTF8_FULL_CONDENSED};
use roomlight_core::closed_loop::PlantConfig;
use roomlight_core::conventional::conventional_start;
use roomlight_core::metrics::patch_delta_e;
use roomlight_core::optimum::optimum;
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use roomlight_core::{LinearRgb, Problem, StepRule};
use roomlight_sim::scene::Scene;
use roomlight_sim::scenes::{HardCase, hard_case_of};
use serde::Serialize;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// What to run.
#[derive(Debug, Clone)]
pub struct Plan {
    /// The small room, fewer captures and rules, a synthetic room of 100 nodes (seconds).
    pub quick: bool,
    /// The default room's presets.
    pub presets: bool,
    /// The hard cases.
    pub hard: bool,
    /// Round cost and memory against the number of nodes (`bench net`).
    pub scaling: bool,
    /// Runs per case and rule (camera noise seeds `seed..seed + repeats`).
    pub repeats: usize,
    pub seed: u64,
    pub json: Option<PathBuf>,
    pub out: Option<PathBuf>,
    /// Only the cases whose name contains this (and the scaling run if it contains it).
    pub case: Option<String>,
}

/// One record of the table and of `--json`: medians over the repeats.
#[derive(Debug, Clone, Serialize)]
pub struct Record {
    pub case: String,
    pub rule: String,
    pub captures_to_1pct: Option<u64>,
    pub captures_to_0_1pct: Option<u64>,
    pub final_excess: f64,
    pub mean_de00: f64,
    pub max_de00: f64,
    pub compute_us_per_round: f64,
    pub message_ms_per_round: f64,
    pub capture_ms: f64,
    pub bytes_per_round: f64,
    /// True when any repeat diverged (a non-finite value, or ending above where it started).
    pub diverged: bool,
    pub captures: u64,
    pub repeats: usize,
    /// The smallest and largest value over the repeats.
    pub spread: Spread,
}

/// `[min, max]` over the repeats (`None`: never reached).
#[derive(Debug, Clone, Serialize)]
pub struct Spread {
    pub captures_to_1pct: [Option<u64>; 2],
    pub final_excess: [f64; 2],
    pub mean_de00: [f64; 2],
    pub max_de00: [f64; 2],
    pub message_ms_per_round: [f64; 2],
}

/// One point of a run: after `capture` captures' rounds.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Point {
    pub capture: u64,
    pub seconds: f64,
    pub excess: f64,
    pub mean_de00: f64,
}

/// A rule's name and its median curve.
pub type Curve = (String, Vec<Point>);

/// One run of one case and rule.
#[derive(Debug, Clone)]
struct Run {
    trace: Vec<Point>,
    /// Captures to a level are counted from here on (the last join or leave).
    settle_from: u64,
    final_excess: f64,
    mean_de00: f64,
    max_de00: f64,
    compute_us_per_round: f64,
    message_ms_per_round: f64,
    capture_ms: f64,
    bytes_per_round: f64,
    captures: u64,
}

impl Run {
    fn first_below(&self, level: f64) -> Option<u64> {
        self.trace
            .iter()
            .find(|p| p.capture >= self.settle_from && p.excess <= level)
            .map(|p| p.capture)
    }

    /// A non-finite value anywhere, an end above the start, or an end far above the best the
    /// run had reached (an oscillation that grew): ten times it and over 10% excess, so that
    /// noise around a small excess does not count.
    fn diverged(&self) -> bool {
        let start = self.trace.first().map_or(f64::INFINITY, |p| p.excess);
        let best = self
            .trace
            .iter()
            .filter(|p| p.capture >= self.settle_from)
            .map(|p| p.excess)
            .fold(f64::INFINITY, f64::min);
        !self.final_excess.is_finite()
            || self
                .trace
                .iter()
                .any(|p| !p.excess.is_finite() || !p.mean_de00.is_finite())
            || self.final_excess > start
            || (self.final_excess > 0.1 && self.final_excess > 10.0 * best)
    }
}

/// Every case's records and median curves, for the table, the JSON and the page.
#[derive(Debug, Default)]
pub struct Outcome {
    pub records: Vec<Record>,
    /// Per case: per rule, the median curve over the repeats.
    pub curves: Vec<(String, Vec<Curve>)>,
    pub sparsity: Vec<super::sparsity::Sparsity>,
    /// The scaling run (`bench net`), when the plan has one.
    pub scaling: Option<crate::bench::net::NetRun>,
    /// Cases that could not run, and why (reported, not left out).
    pub failed: Vec<(String, String)>,
}

/// A rule of the comparison: its name, the node rule, the model rounds per capture, and
/// whether the camera agent discards its stale frames.
type RuleSpec = (&'static str, StepRule, usize, bool);

/// Every rule, or the quick subset; with stale errors also the safe step the delay allows.
fn rules(problem: &Problem, quick_subset: bool, latency: usize) -> Vec<RuleSpec> {
    // The same six rules as `bench core` (the budget does not matter here).
    let mut all: Vec<RuleSpec> = crate::bench::core::rules(problem, 1)
        .into_iter()
        .map(|(name, config)| (name, config.rule, config.model_rounds, false))
        .collect();
    if latency > 0 {
        // Two answers to a late camera: damp the step as the delay rule requires, or discard
        // the late frames and keep the fast rule.
        let momentum = StepRule::Momentum { theta: 1.0 };
        all.push(("safe-delay", StepRule::safe_for_delay(latency), 0, false));
        all.push(("model-20-discard", momentum, 20, true));
    }
    if quick_subset {
        all.retain(|(name, ..)| {
            matches!(
                *name,
                "paper" | "momentum" | "model-20" | "safe-delay" | "model-20-discard"
            )
        });
    }
    all
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn range(v: &[f64]) -> [f64; 2] {
    [
        v.iter().copied().fold(f64::INFINITY, f64::min),
        v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    ]
}

/// Median, min and max of "captures to a level" where never (`None`) counts as infinite.
fn captures_stats(v: &[Option<u64>]) -> (Option<u64>, [Option<u64>; 2]) {
    let mut sorted: Vec<Option<u64>> = v.to_vec();
    sorted.sort_by_key(|c| c.unwrap_or(u64::MAX));
    let pick = |k: usize| sorted.get(k).copied().flatten();
    (
        pick(sorted.len() / 2),
        [pick(0), pick(sorted.len().saturating_sub(1))],
    )
}

/// The record of the repeats of one case and rule, and the median curve.
fn summarise(case: &str, rule: &str, runs: &[Run]) -> (Record, Vec<Point>) {
    let values = |f: fn(&Run) -> f64| runs.iter().map(f).collect::<Vec<f64>>();
    let (to_1, to_1_range) =
        captures_stats(&runs.iter().map(|r| r.first_below(1e-2)).collect::<Vec<_>>());
    let (to_01, _) = captures_stats(&runs.iter().map(|r| r.first_below(1e-3)).collect::<Vec<_>>());
    let spread = Spread {
        captures_to_1pct: to_1_range,
        final_excess: range(&values(|r| r.final_excess)),
        mean_de00: range(&values(|r| r.mean_de00)),
        max_de00: range(&values(|r| r.max_de00)),
        message_ms_per_round: range(&values(|r| r.message_ms_per_round)),
    };
    let record = Record {
        case: case.into(),
        rule: rule.into(),
        captures_to_1pct: to_1,
        captures_to_0_1pct: to_01,
        final_excess: median(&mut values(|r| r.final_excess)),
        mean_de00: median(&mut values(|r| r.mean_de00)),
        max_de00: median(&mut values(|r| r.max_de00)),
        compute_us_per_round: median(&mut values(|r| r.compute_us_per_round)),
        message_ms_per_round: median(&mut values(|r| r.message_ms_per_round)),
        capture_ms: median(&mut values(|r| r.capture_ms)),
        bytes_per_round: median(&mut values(|r| r.bytes_per_round)),
        diverged: runs.iter().any(Run::diverged),
        captures: runs.iter().map(|r| r.captures).max().unwrap_or(0),
        repeats: runs.len(),
        spread,
    };
    // The median curve: capture by capture over the runs that got that far.
    let longest = runs.iter().map(|r| r.trace.len()).max().unwrap_or(0);
    let curve = (0..longest)
        .map(|k| {
            let at: Vec<&Point> = runs.iter().filter_map(|r| r.trace.get(k)).collect();
            Point {
                capture: k as u64,
                seconds: median(&mut at.iter().map(|p| p.seconds).collect::<Vec<_>>()),
                excess: median(&mut at.iter().map(|p| p.excess).collect::<Vec<_>>()),
                mean_de00: median(&mut at.iter().map(|p| p.mean_de00).collect::<Vec<_>>()),
            }
        })
        .collect();
    (record, curve)
}

impl Plan {
    /// True when the case `name` passes the `--case` filter.
    fn wants(&self, name: &str) -> bool {
        self.case.as_deref().is_none_or(|f| name.contains(f))
    }

    /// Refuses a plan that cannot run (before anything is measured).
    pub fn check(&self) -> Result<()> {
        if self.repeats == 0 {
            bail!("--repeats must be at least 1");
        }
        Ok(())
    }

    /// True when the scaling run (`bench net`) is part of the plan and passes the filter.
    pub fn runs_scaling(&self) -> bool {
        self.scaling && self.wants("scaling")
    }
}

/// Runs the plan: prints the tables, writes `--json` and `--out`.
pub fn run(plan: &Plan) -> Result<()> {
    let t0 = Instant::now();
    let mut outcome = measure(plan)?;
    if plan.runs_scaling() {
        outcome.scaling = Some(crate::bench::net::run(plan.quick, None)?);
    }
    finish(plan, &outcome, t0)
}

/// Every case of the plan, the scaling run excepted (the caller runs it, so that it can be
/// reported as a bench of its own).
pub fn measure(plan: &Plan) -> Result<Outcome> {
    plan.check()?;
    let mut outcome = Outcome::default();
    if plan.presets || plan.hard {
        let mut base = if plan.quick {
            roomlight_sim::scenes::small()?
        } else {
            roomlight_sim::scenes::lab()?
        };
        if plan.quick {
            base.camera.resolution = [640, 480];
        }
        // The base room is calibrated once, and only when one of its cases is wanted.
        let mut calibrated: Option<Bench> = None;
        if plan.presets {
            presets(plan, &base, &mut calibrated, &mut outcome)?;
        }
        if plan.hard {
            stale_cases(plan, &base, &mut calibrated, &mut outcome)?;
            churn_cases(plan, &base, &mut calibrated, &mut outcome)?;
            hard_scenes(plan, &base, &mut outcome)?;
            let nodes = if plan.quick { 100 } else { 1000 };
            if plan.wants(&format!("synthetic-{nodes}")) {
                synthetic_case(&mut outcome, plan, nodes, hard_budget(plan))?;
            }
        }
    }
    Ok(outcome)
}

/// Prints the table, the cases that failed and the time since `t0`; writes `--json` and
/// `--out`.
pub fn finish(plan: &Plan, outcome: &Outcome, t0: Instant) -> Result<()> {
    println!("{CAPTION}");
    println!("{}", super::width::split(&mut table(&outcome.records), 2));
    for (case, why) in &outcome.failed {
        println!("{case}: could not run: {why}");
    }
    println!(
        "bench: {:.0} s, {} repeat(s) per case and rule",
        t0.elapsed().as_secs_f64(),
        plan.repeats
    );
    if let Some(path) = &plan.json {
        std::fs::write(path, serde_json::to_string_pretty(&outcome.records)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(dir) = &plan.out {
        crate::bench::report::write(dir, outcome)?;
        println!("report: {}", dir.join("index.html").display());
    }
    Ok(())
}

/// Captures per rule on the hard cases.
fn hard_budget(plan: &Plan) -> u64 {
    if plan.quick { 8 } else { 15 }
}

/// The base room under each LED preset (only the first with `quick`).
fn presets(
    plan: &Plan,
    base: &Scene,
    calibrated: &mut Option<Bench>,
    outcome: &mut Outcome,
) -> Result<()> {
    let budget: u64 = if plan.quick { 8 } else { 30 };
    let presets = if plan.quick { 1 } else { base.presets.len() };
    for (preset, spec) in base.presets.iter().enumerate().take(presets) {
        let name = format!("{}/{}", base.name, spec.name);
        if plan.wants(&name) {
            let variant = Variant::plain(budget);
            Bench::once(calibrated, base, plan.seed)?.case(
                outcome,
                plan,
                &name,
                preset,
                variant,
                preset == 0,
            )?;
        }
    }
    Ok(())
}

/// Errors one and two captures stale (camera latency) on the base room's first preset.
fn stale_cases(
    plan: &Plan,
    base: &Scene,
    calibrated: &mut Option<Bench>,
    outcome: &mut Outcome,
) -> Result<()> {
    for latency in [1, 2] {
        let name = format!("{}/stale-{latency}", base.name);
        if !plan.wants(&name) {
            continue;
        }
        // Discarding late frames spends captures: a longer budget.
        let variant = Variant {
            latency,
            ..Variant::hard(plan, if plan.quick { 10 } else { 20 })
        };
        Bench::once(calibrated, base, plan.seed)?.case(outcome, plan, &name, 0, variant, false)?;
    }
    Ok(())
}

/// A projector leaving and another joining, on the base room's first preset: the joining
/// projector's attenuation known to the camera agent, or measured hot when it joins (its nodes
/// black, then each white: more captures).
fn churn_cases(
    plan: &Plan,
    base: &Scene,
    calibrated: &mut Option<Bench>,
    outcome: &mut Outcome,
) -> Result<()> {
    let (leave_at, join_at) = if plan.quick { (2, 4) } else { (5, 10) };
    for hot in [false, true] {
        let name = format!(
            "{}/leave-{leave_at}-join-{join_at}{}",
            base.name,
            if hot { "-hot" } else { "" }
        );
        if !plan.wants(&name) {
            continue;
        }
        let b = Bench::once(calibrated, base, plan.seed)?;
        match Churn::pick(&b.room, &b.cal, leave_at, join_at, hot) {
            Ok(churn) => {
                let joining = b
                    .cal
                    .regions
                    .iter()
                    .filter(|r| r.projector == churn.joining)
                    .count() as u64;
                let calibration = if hot { joining + 1 } else { 0 };
                let variant = Variant {
                    churn: Some(churn),
                    ..Variant::hard(plan, hard_budget(plan).max(join_at + 8) + calibration)
                };
                b.case(outcome, plan, &name, 0, variant, false)?;
            }
            Err(e) => outcome.failed.push((name, format!("{e:#}"))),
        }
    }
    Ok(())
}

/// The variants of the room (DIM, reflective, …), each calibrated on its own.
fn hard_scenes(plan: &Plan, base: &Scene, outcome: &mut Outcome) -> Result<()> {
    for case in HardCase::ALL {
        let scene = hard_case_of(base.clone(), case)?;
        let name = scene.name.clone();
        if !plan.wants(&name) {
            continue;
        }
        println!("hard case {name}: calibrating");
        let variant = Variant::hard(plan, hard_budget(plan));
        let attempt = Bench::calibrate(scene, plan.seed)
            .and_then(|b| b.case(outcome, plan, &name, 0, variant, false));
        if let Err(e) = attempt {
            // A case the pipeline cannot calibrate or run is reported, not left out.
            println!("  {name}: could not run: {e:#}");
            outcome.failed.push((name, format!("{e:#}")));
        }
    }
    Ok(())
}

/// How a case departs from a plain run.
#[derive(Debug, Clone, Copy)]
struct Variant {
    budget: u64,
    latency: usize,
    churn: Option<Churn>,
    /// Only the paper's rule, momentum and model-20 (the quick bench's hard cases).
    few_rules: bool,
}

impl Variant {
    fn plain(budget: u64) -> Self {
        Self {
            budget,
            latency: 0,
            churn: None,
            few_rules: false,
        }
    }

    /// A hard case: the quick bench runs only a few rules on it.
    fn hard(plan: &Plan, budget: u64) -> Self {
        Self {
            few_rules: plan.quick,
            ..Self::plain(budget)
        }
    }
}

/// A calibrated simulated room, ready to run cases on.
struct Bench {
    room: Arc<roomlight_sim::Room>,
    cal: pipeline::Calibrated,
    transport: pipeline::Transport,
    noise: std::cell::RefCell<roomlight_sim::CameraNoise>,
}

impl Bench {
    /// The bench in `slot`, calibrated on first use.
    fn once<'a>(slot: &'a mut Option<Bench>, scene: &Scene, seed: u64) -> Result<&'a Bench> {
        if slot.is_none() {
            println!("calibrating {}", scene.name);
            *slot = Some(Bench::calibrate(scene.clone(), seed)?);
        }
        slot.as_ref().context("the calibrated room")
    }

    fn calibrate(scene: Scene, seed: u64) -> Result<Self> {
        let room = Arc::new(roomlight_sim::Room::build(scene).context("building the room")?);
        let mut noise = roomlight_sim::CameraNoise::with_seed(&room, seed);
        let bar = indicatif::ProgressBar::hidden();
        let cal = pipeline::calibrate(&room, &mut noise, &bar, |line| println!("  {line}"))?;
        let basis = Arc::new(roomlight_sim::NodeBasis::new(&room, &cal.regions, None)?);
        let transport =
            pipeline::Transport::new(basis, &cal.corners, pipeline::sample_config(&room))?;
        Ok(Self {
            room,
            cal,
            transport,
            noise: std::cell::RefCell::new(noise),
        })
    }

    /// Every rule on `preset`, `plan.repeats` times each.
    fn case(
        &self,
        outcome: &mut Outcome,
        plan: &Plan,
        name: &str,
        preset: usize,
        variant: Variant,
        report_sparsity: bool,
    ) -> Result<()> {
        let model =
            pipeline::measure_target(&self.room, &self.cal, preset, &mut self.noise.borrow_mut())?;
        let truth = pipeline::Truth::new(&self.room, &self.transport, &model, preset)?;
        if report_sparsity {
            outcome
                .sparsity
                .push(super::sparsity::scene_sparsity(name, &self.cal, &model)?);
        }
        let bar = indicatif::ProgressBar::hidden();
        let mut curves = Vec::new();
        for (rule_name, rule, model_rounds, discard_stale) in
            rules(&model.problem, variant.few_rules, variant.latency)
        {
            let compute_us_per_round =
                crate::bench::core::us_per_node_update(&model.problem, rule, &model.conventional)?
                    * model.problem.nodes() as f64;
            let mut runs = Vec::new();
            for k in 0..plan.repeats {
                let options = RunOptions {
                    rule,
                    model_rounds,
                    max_captures: variant.budget,
                    stop_when_settled: false,
                    seed: plan.seed + k as u64,
                    latency: variant.latency,
                    discard_stale,
                    churn: variant.churn,
                };
                let r = pipeline::run_agents(
                    &self.room,
                    &self.cal,
                    &model,
                    &self.transport,
                    &truth,
                    options,
                    &bar,
                )?;
                let settle_from = variant.churn.map_or(0, |c| c.join_at.max(c.leave_at) + 1);
                runs.push(scene_run(&r, compute_us_per_round, settle_from));
            }
            let (record, curve) = summarise(name, rule_name, &runs);
            println!(
                "  {name} {rule_name}: to 1% {}, final excess {:.1e}, mean ΔE00 {:.2}",
                record
                    .captures_to_1pct
                    .map_or("never".into(), |c| c.to_string()),
                record.final_excess,
                record.mean_de00
            );
            outcome.records.push(record);
            curves.push((rule_name.to_string(), curve));
        }
        outcome.curves.push((name.to_string(), curves));
        Ok(())
    }
}

/// A run of the simulated room as the bench counts it: the measured model's excess (the
/// quantity the rules minimise) against captures and wall time.
fn scene_run(r: &RunResult, compute_us_per_round: f64, settle_from: u64) -> Run {
    let rounds = r.rounds.max(1) as f64;
    let compute_s = compute_us_per_round * rounds * 1e-6;
    Run {
        trace: r
            .trace
            .iter()
            .map(|p| Point {
                capture: p.capture,
                seconds: p.seconds,
                excess: p.model_excess,
                mean_de00: p.mean_de00,
            })
            .collect(),
        settle_from,
        final_excess: r.trace.last().map_or(f64::NAN, |p| p.model_excess),
        mean_de00: crate::report::mean(&r.de00),
        max_de00: r.de00.iter().copied().fold(0.0, f64::max),
        compute_us_per_round,
        // Messages: what is left of the wall time after the camera and the node updates.
        message_ms_per_round: ((r.seconds - r.capture_seconds - compute_s).max(0.0) / rounds) * 1e3,
        capture_ms: r.capture_seconds * 1e3 / r.captures.max(1) as f64,
        bytes_per_round: r.bytes_per_round,
        captures: r.captures,
    }
}

/// A synthetic room of `nodes` nodes and 24 patches each (no rendering: the transport is
/// written down), with the camera's noise, through the agents on loopback for every rule.
fn synthetic_case(outcome: &mut Outcome, plan: &Plan, nodes: usize, budget: u64) -> Result<()> {
    let name = format!("synthetic-{nodes}");
    let room = synthetic_room(&SyntheticConfig::new(nodes, plan.seed))?;
    let problem = room.problem;
    println!(
        "{name}: {nodes} nodes over {} patches, optimum…",
        problem.patches()
    );
    let best = optimum(&problem)?;
    let start = conventional_start(&problem, &room.charts, LinearRgb::splat(0.5))?;
    outcome.sparsity.push(super::sparsity::synthetic_sparsity(
        &name, nodes, plan.seed,
    )?);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the runtime")?;
    let mut curves = Vec::new();
    for (rule_name, rule, model_rounds, _) in rules(&problem, false, 0) {
        let compute_us_per_round =
            crate::bench::core::us_per_node_update(&problem, rule, &start)? * nodes as f64;
        let mut runs = Vec::new();
        for k in 0..plan.repeats {
            let seed = plan.seed + k as u64;
            let mut run = runtime.block_on(synthetic_run(
                &problem,
                &start,
                (rule, model_rounds),
                budget,
                seed,
            ))?;
            run.compute_us_per_round = compute_us_per_round;
            run.trace.iter_mut().for_each(|p| {
                p.excess = best.excess(p.excess);
            });
            run.final_excess = run.trace.last().map_or(f64::NAN, |p| p.excess);
            runs.push(run);
        }
        let (record, curve) = summarise(&name, rule_name, &runs);
        println!(
            "  {name} {rule_name}: to 1% {}, final excess {:.1e}",
            record
                .captures_to_1pct
                .map_or("never".into(), |c| c.to_string()),
            record.final_excess
        );
        outcome.records.push(record);
        curves.push((rule_name.to_string(), curve));
    }
    outcome.curves.push((name, curves));
    Ok(())
}

/// One run on the synthetic room; the trace holds the true `G` (the caller turns it into excess).
async fn synthetic_run(
    problem: &Problem,
    start: &[LinearRgb],
    (rule, model_rounds): (StepRule, usize),
    budget: u64,
    seed: u64,
) -> Result<Run> {
    let plant = PlantConfig {
        noise_scale: 1.0,
        seed,
        ..PlantConfig::default()
    };
    let mut agents = crate::bench::net::SyntheticAgents::camera(
        problem,
        plant,
        Some(start.to_vec()),
        model_rounds,
    )
    .await?;
    let de = |x: &[LinearRgb]| -> Result<f64> {
        Ok(patch_delta_e(problem.target(), &problem.response(x))?.mean)
    };
    let t0 = Instant::now();
    let mut trace = vec![Point {
        capture: 0,
        seconds: 0.0,
        excess: problem.objective(start),
        mean_de00: de(start)?,
    }];
    agents.spawn_nodes(rule);
    let mut bytes = pipeline::PerRound::default();
    let expected = agents.agents;
    // The rounds start with the first agent that joins (as in a room); the budget counts from
    // the capture at which the last one has joined, so that a slow join (a loaded machine)
    // cannot spend it on a partial room and end the run before the late nodes have moved.
    let mut complete_at: Option<u64> = None;
    let outcome = tokio::time::timeout(Duration::from_secs(300), async {
        loop {
            agents.status.changed().await?;
            let s = agents.status.borrow().clone();
            bytes.add(&s);
            let x = agents.room.shown();
            trace.push(Point {
                capture: s.captures,
                seconds: t0.elapsed().as_secs_f64(),
                excess: agents.room.true_objective(),
                mean_de00: de(&x)?,
            });
            if s.live_projectors == expected {
                let from = *complete_at.get_or_insert(s.captures);
                if s.captures >= from + budget {
                    return Ok::<_, anyhow::Error>(s);
                }
            }
        }
    })
    .await;
    let seconds = t0.elapsed().as_secs_f64();
    let x = agents.room.shown();
    agents.stop().await;
    let last = outcome.context("the synthetic room's agents did not finish within 300 s")??;
    let de_final = patch_delta_e(problem.target(), &problem.response(&x))?;
    let rounds = last.round.max(1) as f64;
    Ok(Run {
        trace,
        settle_from: 0,
        final_excess: f64::NAN,
        mean_de00: de_final.mean,
        max_de00: de_final.per_patch.iter().copied().fold(0.0, f64::max),
        compute_us_per_round: 0.0,
        message_ms_per_round: seconds * 1e3 / rounds,
        capture_ms: 0.0,
        bytes_per_round: bytes.bytes_per_round(),
        captures: last.captures,
    })
}

/// What the table of records shows, printed above it.
pub const CAPTION: &str = "medians over the repeats (range in brackets); captures to 1% / 0.1% excess over the model's G*, from the conventional start (capture 0), through the agents on loopback; after a leave and a join they count from the join";

/// The records as a table (a terminal's preset; the caller may load another).
pub fn table(records: &[Record]) -> Table {
    let mut table = Table::new();
    super::width::fit(&mut table);
    table.load_preset(UTF8_FULL_CONDENSED).set_header([
        "case",
        "rule",
        "to 1%",
        "to 0.1%",
        "final excess (range)",
        "mean ΔE00 (range)",
        "max ΔE00",
        "compute µs/round",
        "message ms/round",
        "capture ms",
        "bytes/round",
        "diverged",
    ]);
    for r in records {
        table.add_row([
            r.case.clone(),
            r.rule.clone(),
            captures_cell(r.captures_to_1pct, r.spread.captures_to_1pct, r.captures),
            captures_cell(r.captures_to_0_1pct, [None, None], r.captures),
            format!(
                "{:.1e} ({:.1e}…{:.1e})",
                r.final_excess, r.spread.final_excess[0], r.spread.final_excess[1]
            ),
            format!(
                "{:.2} ({:.2}…{:.2})",
                r.mean_de00, r.spread.mean_de00[0], r.spread.mean_de00[1]
            ),
            format!("{:.2}", r.max_de00),
            format!("{:.1}", r.compute_us_per_round),
            format!("{:.2}", r.message_ms_per_round),
            format!("{:.0}", r.capture_ms),
            format!("{:.0}", r.bytes_per_round),
            r.diverged.to_string(),
        ]);
    }
    table
}

/// "3" or "3 (2…5)" or "> 30".
pub fn captures_cell(median: Option<u64>, range: [Option<u64>; 2], budget: u64) -> String {
    let one = |c: Option<u64>| c.map_or(format!("> {budget}"), |c| c.to_string());
    if range[0] == range[1] || range == [None, None] {
        one(median)
    } else {
        format!("{} ({}…{})", one(median), one(range[0]), one(range[1]))
    }
}
