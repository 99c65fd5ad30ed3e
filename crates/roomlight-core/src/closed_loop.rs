//! An in-memory closed loop for comparing rules without a network (issue: core §6).
//!
//! A [`Plant`] stands in for projectors and camera: the true transport `P`, `d`, optional capture
//! noise, an optional projector gamma the nodes do not know, a camera saturation level, and
//! nodes that leave at a given capture. [`run`] drives one [`NodeState`] per node and the
//! round [`Controller`] the camera agent drives too (when to capture, model rounds, restarts,
//! settling), counting captures and model rounds separately.
//!
//! It knows nothing of messages or agents: a round here is a loop over the nodes.

use crate::aggregator::{ErrorAggregator, RoundSummary};
use crate::model::{ModelError, PatchId, Problem, check_len};
use crate::rgb::LinearRgb;
use crate::round::Controller;
pub use crate::round::objective_noise;
use crate::rules::{NodeState, StepRule};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// Half a display code step for 8-bit output: the stop threshold of DESIGN §3.6.
pub const HALF_CODE_STEP: f64 = 1.0 / 510.0;

/// How the simulated room departs from the nodes' model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlantConfig {
    /// Multiplies the problem's per-patch noise `σ` for capture noise; 0 for a noiseless camera.
    pub noise_scale: f64,
    /// Seed of the capture noise.
    pub seed: u64,
    /// Projector gamma the nodes do not know: the light is `x^γ`. 1 for linearised projectors.
    pub gamma: f64,
    /// Camera saturation: captured channels are clipped at this value. `None`: never saturates.
    pub saturation: Option<f64>,
    /// `(node, capture)`: the node's light is gone from that capture on.
    pub departures: Vec<(usize, usize)>,
}

impl Default for PlantConfig {
    fn default() -> Self {
        Self {
            noise_scale: 0.0,
            seed: 0,
            gamma: 1.0,
            saturation: None,
            departures: Vec::new(),
        }
    }
}

/// The simulated room of the closed loop.
#[derive(Debug, Clone)]
pub struct Plant {
    truth: Problem,
    config: PlantConfig,
    rng: ChaCha8Rng,
}

impl Plant {
    /// A plant around the true problem.
    pub fn new(truth: Problem, config: PlantConfig) -> Result<Self, ModelError> {
        let positive = |what, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(ModelError::Parameter {
                    what,
                    value: v,
                    expected: "a finite number > 0",
                })
            }
        };
        positive("gamma", config.gamma)?;
        if config.noise_scale != 0.0 {
            positive("noise scale", config.noise_scale)?;
        }
        if let Some(s) = config.saturation {
            positive("saturation", s)?;
        }
        let rng = ChaCha8Rng::seed_from_u64(config.seed);
        Ok(Self { truth, config, rng })
    }

    /// The true problem.
    pub fn truth(&self) -> &Problem {
        &self.truth
    }

    /// True when node `n` is still in the room at `capture`.
    pub fn present(&self, n: usize, capture: usize) -> bool {
        !self
            .config
            .departures
            .iter()
            .any(|&(node, at)| node == n && capture >= at)
    }

    /// The true problem as it stands at `capture` (without the nodes that left): its optimum
    /// is what the loop should reach.
    pub fn truth_at(&self, capture: usize) -> Problem {
        let gone: Vec<usize> = (0..self.truth.nodes())
            .filter(|&n| !self.present(n, capture))
            .collect();
        self.truth.without_nodes(&gone)
    }

    /// The linear light each node really emits for its shown values.
    fn emitted(&self, shown: &[LinearRgb], capture: usize) -> Vec<LinearRgb> {
        let gamma = self.config.gamma;
        shown
            .iter()
            .enumerate()
            .map(|(n, &x)| {
                if self.present(n, capture) {
                    x.clamp_unit().map(|v| v.powf(gamma))
                } else {
                    LinearRgb::ZERO
                }
            })
            .collect()
    }

    /// The noiseless patch values for the shown node values.
    pub fn true_response(&self, shown: &[LinearRgb], capture: usize) -> Vec<LinearRgb> {
        self.truth.response(&self.emitted(shown, capture))
    }

    /// The true `G` for the shown node values.
    pub fn true_objective(&self, shown: &[LinearRgb], capture: usize) -> f64 {
        self.truth.objective(&self.emitted(shown, capture))
    }

    /// One capture: true response plus Gaussian noise `σ_i · noise_scale`, clipped at zero
    /// and at saturation.
    pub fn capture(&mut self, shown: &[LinearRgb], capture: usize) -> Vec<LinearRgb> {
        let mut y = self.true_response(shown, capture);
        let scale = self.config.noise_scale;
        let saturation = self.config.saturation.unwrap_or(f64::INFINITY);
        for (yi, sigma) in y.iter_mut().zip(self.truth.noise()) {
            for c in 0..3 {
                let z: f64 = StandardNormal.sample(&mut self.rng);
                yi[c] = (yi[c] + scale * sigma[c] * z).clamp(0.0, saturation);
            }
        }
        y
    }
}

/// How the loop runs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LoopConfig {
    /// Every node's rule.
    pub rule: StepRule,
    /// Model rounds after each measured round (DESIGN §3.4); 0 for none.
    pub model_rounds: usize,
    /// Age in captures of the errors the nodes use (0: fresh). Not combined with model rounds.
    pub delay: usize,
    /// Capture budget, the conventional start's capture included.
    pub max_captures: usize,
    /// Stop (DESIGN §3.6) when no node moved by more than [`HALF_CODE_STEP`] in the last
    /// cycle, or when the measured `G` has settled ([`crate::round::Settle`]: it changed by less than its own
    /// noise in two captures running): with a real camera the noise keeps every node moving a
    /// little, and the second test ends the flicker.
    pub stop_when_settled: bool,
    /// Benchmark oracle: stop once the plant's true `G` is at or below this value. A real
    /// camera does not know the true `G`; benchmarks use it to stop runs that are done.
    pub stop_at_true_objective: Option<f64>,
    /// The most captures averaged ([`crate::round::Controller`]; 1: every capture alone).
    pub average: usize,
}

impl LoopConfig {
    /// A plain loop: this rule, no model rounds, fresh errors, no early stop.
    pub fn new(rule: StepRule, max_captures: usize) -> Self {
        Self {
            rule,
            model_rounds: 0,
            delay: 0,
            max_captures,
            stop_when_settled: false,
            stop_at_true_objective: None,
            average: crate::round::AVERAGE_CAPTURES,
        }
    }
}

/// What one capture saw.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CaptureRecord {
    /// Capture number, from 1 (the start).
    pub capture: usize,
    /// Model rounds run before this capture, in total.
    pub model_rounds: usize,
    /// `G` from the measured errors.
    pub measured_objective: f64,
    /// `G` of the shown values on the true, noiseless plant.
    pub true_objective: f64,
    /// Largest `|Δx|` of any node and channel in the cycle before this capture.
    pub max_step: f64,
}

/// Why the loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum StopReason {
    /// The capture budget was spent.
    Budget,
    /// Every node moved less than half a code step.
    Settled,
    /// `G` stopped changing by more than its measurement noise.
    NoiseFloor,
    /// The benchmark oracle's objective was reached.
    Reached,
}

/// The record of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Trace {
    /// One record per capture.
    pub records: Vec<CaptureRecord>,
    /// The values shown at the end, one per node.
    pub shown: Vec<LinearRgb>,
    /// Why it ended.
    pub stop: StopReason,
    /// Node updates computed (all rounds, all nodes).
    pub node_updates: usize,
}

impl Trace {
    /// Captures until the true `G` first reaches `target` (`None` if never).
    pub fn captures_to(&self, target_objective: f64) -> Option<usize> {
        self.records
            .iter()
            .find(|r| r.true_objective <= target_objective)
            .map(|r| r.capture)
    }

    /// The last record.
    pub fn last(&self) -> Option<&CaptureRecord> {
        self.records.last()
    }
}

/// What went wrong in a run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LoopError {
    /// Inconsistent inputs.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// Delay and model rounds together are not defined.
    #[error(
        "delay {delay} with {model_rounds} model rounds: stale errors and model rounds do not combine"
    )]
    DelayWithModelRounds { delay: usize, model_rounds: usize },
}

/// Runs the loop: nodes built from `model` (the nodes' measured view: `P̂`, `r`, `d`) start at
/// `start`; the plant supplies captures.
pub fn run(
    model: &Problem,
    plant: &mut Plant,
    start: &[LinearRgb],
    config: &LoopConfig,
) -> Result<Trace, LoopError> {
    run_observed(model, plant, start, config, |_, _, _| {})
}

/// [`run`], calling `observe(record, shown values, plant)` after every capture (live progress,
/// per-capture metrics).
pub fn run_observed(
    model: &Problem,
    plant: &mut Plant,
    start: &[LinearRgb],
    config: &LoopConfig,
    mut observe: impl FnMut(&CaptureRecord, &[LinearRgb], &Plant),
) -> Result<Trace, LoopError> {
    check_inputs(model, plant, start, config)?;
    let mut nodes = build_nodes(model, config.rule, start)?;
    let mut controller =
        Controller::new(model.noise().to_vec(), config.model_rounds).averaging(config.average);
    let mut stale: VecDeque<(Vec<LinearRgb>, bool)> = VecDeque::new();
    let mut records = Vec::new();
    let mut model_rounds = 0;
    let mut node_updates = 0;
    let mut max_step = 0.0;
    let mut stop = StopReason::Budget;
    for capture in 1..=config.max_captures {
        let shown: Vec<LinearRgb> = nodes.iter().map(NodeState::shown).collect();
        let summary = measure(model, plant, &shown, capture, &mut controller)?;
        let record = CaptureRecord {
            capture,
            model_rounds,
            measured_objective: summary.objective,
            true_objective: plant.true_objective(&shown, capture),
            max_step,
        };
        observe(&record, &shown, plant);
        records.push(record);
        if let Some(reason) = stopped(config, &records, capture, max_step, &controller) {
            stop = reason;
            break;
        }
        if capture == config.max_captures {
            break;
        }
        let active: Vec<bool> = (0..nodes.len())
            .map(|n| plant.present(n, capture + 1))
            .collect();
        // The errors the nodes act on: this capture's, or the one `delay` captures old.
        stale.push_back((controller.errors().to_vec(), summary.restart));
        if stale.len() <= config.delay {
            max_step = 0.0;
            continue;
        }
        let Some((errors, restart)) = stale.pop_front() else {
            continue;
        };
        let (step, rounds, updates) =
            node_rounds(&mut nodes, &active, &errors, restart, &mut controller)?;
        max_step = step;
        model_rounds += rounds;
        node_updates += updates;
    }
    Ok(Trace {
        records,
        shown: nodes.iter().map(NodeState::shown).collect(),
        stop,
        node_updates,
    })
}

/// The loop's inputs agree with each other: one start value per node, a plant of the model's
/// size, and not both stale errors and model rounds.
fn check_inputs(
    model: &Problem,
    plant: &Plant,
    start: &[LinearRgb],
    config: &LoopConfig,
) -> Result<(), LoopError> {
    check_len("start values", start.len(), model.nodes())?;
    check_len("plant nodes", plant.truth().nodes(), model.nodes())?;
    check_len("plant patches", plant.truth().patches(), model.patches())?;
    if config.delay > 0 && config.model_rounds > 0 {
        return Err(LoopError::DelayWithModelRounds {
            delay: config.delay,
            model_rounds: config.model_rounds,
        });
    }
    Ok(())
}

/// Capture `capture` of what the nodes show, through the plant: the controller takes its
/// errors against the model's target and how many nodes are gone by now.
fn measure(
    model: &Problem,
    plant: &mut Plant,
    shown: &[LinearRgb],
    capture: usize,
    controller: &mut Controller,
) -> Result<RoundSummary, LoopError> {
    let measured = plant.capture(shown, capture);
    let errors: Vec<LinearRgb> = model
        .target()
        .iter()
        .zip(&measured)
        .map(|(&r, &y)| r - y)
        .collect();
    // The nodes gone by now are the loop's live projectors changing (departures are final).
    let gone = (0..shown.len())
        .filter(|&n| !plant.present(n, capture))
        .count();
    controller.live(gone as u64);
    Ok(controller.measured(errors)?)
}

/// Why the loop ends after capture `capture`, if it does: the oracle's objective reached,
/// every node settled, or `G` at its noise floor.
fn stopped(
    config: &LoopConfig,
    records: &[CaptureRecord],
    capture: usize,
    max_step: f64,
    controller: &Controller,
) -> Option<StopReason> {
    if let Some(goal) = config.stop_at_true_objective
        && records
            .last()
            .is_some_and(|r: &CaptureRecord| r.true_objective <= goal)
    {
        return Some(StopReason::Reached);
    }
    let settled = capture > 1 + config.delay && max_step < HALF_CODE_STEP;
    if config.stop_when_settled && settled {
        return Some(StopReason::Settled);
    }
    // The one settle rule, as the camera agent applies it.
    if config.stop_when_settled && controller.settled() {
        return Some(StopReason::NoiseFloor);
    }
    None
}

/// The nodes' round on `errors`, then the model rounds the controller asks for: the largest
/// step, the model rounds run and the node updates computed.
fn node_rounds(
    nodes: &mut [NodeState],
    active: &[bool],
    errors: &[LinearRgb],
    restart: bool,
    controller: &mut Controller,
) -> Result<(f64, usize, usize), LoopError> {
    let mut max_step = distributed_round(nodes, active, errors, restart, controller)?;
    let mut model_rounds = 0;
    let mut node_updates = active.iter().filter(|&&a| a).count();
    while let Some(summary) = controller.predicted() {
        let errors = controller.errors().to_vec();
        let step = distributed_round(nodes, active, &errors, summary.restart, controller)?;
        max_step = f64::max(max_step, step);
        model_rounds += 1;
        node_updates += active.iter().filter(|&&a| a).count();
    }
    Ok((max_step, model_rounds, node_updates))
}

/// One node state per column of `model`, each given `s` on its own support and its start value.
pub fn build_nodes(
    model: &Problem,
    rule: StepRule,
    start: &[LinearRgb],
) -> Result<Vec<NodeState>, ModelError> {
    check_len("start values", start.len(), model.nodes())?;
    let s = model.white_response();
    model
        .columns()
        .iter()
        .enumerate()
        .map(|(n, column)| {
            NodeState::new(
                column.clone(),
                &model.white_response_on_support(&s, n),
                rule,
                start[n],
            )
        })
        .collect()
}

/// Where a round's contributions go: the camera's errors, held by an [`ErrorAggregator`] or
/// by the [`Controller`] that holds one.
pub trait Contributions {
    /// One node's contribution change `δ_n` on its support; refused whole if malformed.
    fn add(
        &mut self,
        delta: impl IntoIterator<Item = (PatchId, LinearRgb)>,
    ) -> Result<(), ModelError>;
}

impl Contributions for ErrorAggregator {
    fn add(
        &mut self,
        delta: impl IntoIterator<Item = (PatchId, LinearRgb)>,
    ) -> Result<(), ModelError> {
        self.add_contribution(delta)
    }
}

impl Contributions for Controller {
    fn add(
        &mut self,
        delta: impl IntoIterator<Item = (PatchId, LinearRgb)>,
    ) -> Result<(), ModelError> {
        self.contribution(delta)
    }
}

/// One round for every active node: gather its errors on its support, update, hand its
/// contribution to `contributions`. Returns the largest `|Δx|`. This is the whole per-round
/// compute of the distributed system, without the messages.
pub fn distributed_round(
    nodes: &mut [NodeState],
    active: &[bool],
    errors: &[LinearRgb],
    restart: bool,
    contributions: &mut impl Contributions,
) -> Result<f64, ModelError> {
    let mut max_step = 0.0f64;
    let mut local = Vec::new();
    for (node, _) in nodes.iter_mut().zip(active).filter(|(_, a)| **a) {
        local.clear();
        local.extend(node.column().support().iter().map(|&i| errors[i as usize]));
        let delta = node.update(&local, restart)?;
        max_step = max_step.max(delta.max_abs());
        contributions.add(node.contribution(delta))?;
    }
    Ok(max_step)
}
