//! `roomlight bench` and `roomlight bench room`: speed against error, through the real agents on
//! loopback from the conventional start, for every rule — on the simulated default room (each
//! LED preset), on the hard cases of DESIGN §9, and on a synthetic room of a thousand nodes.
//! Captures to 1% and 0.1% excess over the model's `G*`, final excess and ΔE00, and where the
//! time goes: the simulated camera, the node updates (timed separately on the same problem),
//! the messages (the rest); the wall-clock time to 1% with a video camera and with a DSLR,
//! calibration included; each case's noise floor. Every figure is the median of repeated runs
//! (camera noise seeds) with its range. At one seed every figure but the timings is the same
//! on every run and machine (`pipeline::run`, `pipeline::gate`). Timings are printed and
//! compared, never asserted.
//!
//! This module runs the cases; `records` summarises and prints them, `floor` computes the noise
//! floor, `synthetic` runs the synthetic room.

mod floor;
mod records;
mod synthetic;

pub use floor::Floor;
pub use records::{
    CAPTION, Curve, DSLR_SHOT, FLOOR_NOTE, Point, Record, Spread, TIME_NOTE, VIDEO_SHOT,
    captures_cell, table,
};
use records::{Calibration, Run, summarise};
pub use synthetic::synthetic_trace;

use crate::pipeline::{self, Churn, RunDetail, RunOptions};
use anyhow::{Context, Result, bail};
use roomlight_core::{Problem, StepRule};
use roomlight_sim::scene::Scene;
use roomlight_sim::scenes::{HardCase, hard_case_of};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

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
    /// Per case with churn: the capture after which each event lands and what it is ("wall-left
    /// leaves"), for the markers of its plots.
    pub events: Vec<(String, Vec<(u64, String)>)>,
}

/// A rule of the comparison: its name, the node rule, the model rounds per capture, and
/// whether the camera agent discards its stale frames.
type RuleSpec = (&'static str, StepRule, usize, bool);

/// Model rounds per capture of the bench's default rule (`model-100`): the camera agent's
/// default, which the pipeline's default rule uses too.
pub const MODEL_ROUNDS: usize = roomlight_agent::camera::DEFAULT_MODEL_ROUNDS;

/// Every rule, or the quick subset; with stale errors also the safe step the delay allows.
fn rules(problem: &Problem, quick_subset: bool, latency: usize) -> Vec<RuleSpec> {
    // The same six rules as `bench core` (the budget does not matter here).
    let mut all: Vec<RuleSpec> = crate::bench::core::rules(problem, 1)
        .into_iter()
        .map(|(name, config)| (name, config.rule, config.model_rounds, false))
        .collect();
    // Enough model rounds between two captures for the momentum rule to reach the model's
    // optimum from where the capture left it: on the quick hard cases 100 rounds take the
    // reflective room from 5 captures to 2, the node without a chart from 6 to 1, a single
    // stale capture from 4 to 2; 400 rounds changed only the reflective room's 2 to 1
    // (docs/results.md).
    let momentum = StepRule::Momentum { theta: 1.0 };
    all.push(("model-100", momentum, MODEL_ROUNDS, false));
    if latency > 0 {
        // Two answers to a late camera: damp the step as the delay rule requires, or discard
        // the late frames and keep the fast rule.
        all.push(("safe-delay", StepRule::safe_for_delay(latency), 0, false));
        all.push(("model-100-discard", momentum, MODEL_ROUNDS, true));
    }
    if quick_subset {
        all.retain(|(name, ..)| {
            matches!(
                *name,
                "paper" | "momentum" | "model-100" | "safe-delay" | "model-100-discard"
            )
        });
    }
    all
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
                synthetic::synthetic_case(&mut outcome, plan, nodes, hard_budget(plan))?;
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
    println!("{TIME_NOTE}");
    println!("{FLOOR_NOTE}");
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
    /// Only the paper's rule, momentum and model-100 (the quick bench's hard cases).
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
    /// Wall time of the calibration in the simulator (its captures' rendering included).
    calibration_seconds: f64,
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
        let t0 = Instant::now();
        // Patches on the target too (through the same captures), for the presets that keep it
        // dark (the paper's); the others leave them out of their model.
        let cal =
            pipeline::calibrate_with(&room, true, &mut noise, &bar, |line| println!("  {line}"))?;
        let calibration_seconds = t0.elapsed().as_secs_f64();
        let transport = pipeline::Transport::new(&room, &cal.regions, cal.setup())?;
        Ok(Self {
            room,
            cal,
            transport,
            noise: std::cell::RefCell::new(noise),
            calibration_seconds,
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
        // The preset's own dark-target weight (the paper's 10), as the demo takes it.
        let dark_weight = self
            .room
            .scene()
            .presets
            .get(preset)
            .map_or(0.0, |p| p.dark_weight);
        let lit =
            pipeline::measure_lit(&self.room, &self.cal, preset, &mut self.noise.borrow_mut())?;
        let model = pipeline::Model::for_weight(&self.cal, &lit, dark_weight)?;
        let truth = pipeline::Truth::new(&self.room, &self.transport, &model, preset)?;
        if report_sparsity {
            outcome
                .sparsity
                .push(super::sparsity::scene_sparsity(name, &self.cal, &model)?);
        }
        let bar = indicatif::ProgressBar::hidden();
        let mut curves = Vec::new();
        // From the first run: the calibration's computation and the case's noise floor.
        let mut first: Option<(Calibration, Option<Floor>)> = None;
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
                let r = pipeline::run_detailed(
                    &self.room,
                    &self.cal,
                    &model,
                    &self.transport,
                    &truth,
                    options,
                    &bar,
                )?;
                if first.is_none() {
                    first = Some(self.first_run(&model, &truth, &r, variant)?);
                }
                runs.push(scene_run(&r, compute_us_per_round));
            }
            let (calibration, floor) = first.unwrap_or_default();
            let (record, curve) = summarise((name, rule_name), &runs, calibration, floor);
            println!(
                "  {name} {rule_name}: to 1% {} (true {}), final excess {:.1e} (true {:.1e}), \
mean ΔE00 {:.2}",
                record
                    .captures_to_1pct
                    .map_or("never".into(), |c| c.to_string()),
                record
                    .captures_to_1pct_true
                    .map_or("never".into(), |c| c.to_string()),
                record.final_excess,
                record.final_true_excess,
                record.mean_de00
            );
            outcome.records.push(record);
            curves.push((rule_name.to_string(), curve));
        }
        outcome.curves.push((name.to_string(), curves));
        if let Some(c) = variant.churn {
            let projector = |k: usize| self.room.projectors()[k].name.clone();
            outcome.events.push((
                name.to_string(),
                vec![
                    (c.leave_at, format!("{} leaves", projector(c.leaving))),
                    (c.join_at, format!("{} joins", projector(c.joining))),
                ],
            ));
        }
        Ok(())
    }
}

impl Bench {
    /// What the first run of a case tells about the whole case: the calibration's computation
    /// (its wall time less its captures at this run's mean capture time: the simulator's
    /// rendering is not the room's) and the noise floor (not for a leave and a join: the room
    /// changes under it).
    fn first_run(
        &self,
        model: &pipeline::Model,
        truth: &pipeline::Truth,
        d: &RunDetail,
        variant: Variant,
    ) -> Result<(Calibration, Option<Floor>)> {
        let r = &d.result;
        let capture_s = r.capture_seconds / r.captures.max(1) as f64;
        let calibration = Calibration {
            captures: self.cal.captures,
            compute_seconds: (self.calibration_seconds - self.cal.captures as f64 * capture_s)
                .max(0.0),
        };
        let floor = match variant.churn {
            Some(_) => None,
            None => floor::floor(&model.problem, &truth.problem, &d.best, &d.noise)?,
        };
        Ok((calibration, floor))
    }
}

/// A run of the simulated room as the bench counts it: the measured model's excess (the
/// quantity the rules minimise) against captures and wall time.
fn scene_run(d: &RunDetail, compute_us_per_round: f64) -> Run {
    let r = &d.result;
    let rounds = r.rounds.max(1) as f64;
    let compute_s = compute_us_per_round * rounds * 1e-6;
    let rounds_s = d.rounds_seconds.last().copied().unwrap_or(0.0);
    Run {
        trace: r
            .trace
            .iter()
            .zip(&d.rounds_seconds)
            .map(|(p, &rounds_seconds)| Point {
                capture: p.capture,
                seconds: p.seconds,
                excess: p.model_excess,
                true_excess: p.true_excess,
                mean_de00: p.mean_de00,
                rounds_seconds,
            })
            .collect(),
        joined_after: d.joined_after,
        final_excess: r.trace.last().map_or(f64::NAN, |p| p.model_excess),
        final_true_excess: r.trace.last().map_or(f64::NAN, |p| p.true_excess),
        final_excess_rgb: d.final_excess_rgb,
        mean_de00: crate::report::mean(&r.de00),
        max_de00: r.de00.iter().copied().fold(0.0, f64::max),
        compute_us_per_round,
        // Messages: what is left of the rounds' wall time after the node updates.
        message_ms_per_round: ((rounds_s - compute_s).max(0.0) / rounds) * 1e3,
        capture_ms: r.capture_seconds * 1e3 / r.captures.max(1) as f64,
        bytes_per_round: r.bytes_per_round,
        captures: r.captures,
    }
}
