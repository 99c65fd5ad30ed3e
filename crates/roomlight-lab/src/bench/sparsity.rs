//! Model only what the scene needs: how many attenuation entries the support's cut-off keeps
//! (`SUPPORT_SIGMAS`; 3σ on the synthetic rooms), the bytes a round saves with supports, and
//! what the cut-off costs open-loop and in the closed loop — on the simulated rooms and on
//! synthetic ones.

use crate::pipeline;
use anyhow::Result;
use roomlight_core::closed_loop::{self, LoopConfig, Plant, PlantConfig};
use roomlight_core::conventional::conventional_start;
use roomlight_core::optimum::optimum;
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use roomlight_core::{LinearRgb, Problem, StepRule};
use serde::Serialize;

/// Model only what the scene needs: how much the cut-off keeps and what it costs.
#[derive(Debug, Clone, Serialize)]
pub struct Sparsity {
    pub case: String,
    pub nodes: usize,
    pub patches: usize,
    /// Attenuation entries kept in the supports, and all non-zero ones measured.
    pub kept: usize,
    pub nonzero: usize,
    /// Bytes per round (errors out, contributions in: a patch id and three doubles each) with
    /// supports, and with dense errors to every node.
    pub sparse_bytes: usize,
    pub dense_bytes: usize,
    /// Excess on the uncut model of the cut model's optimum.
    pub cutoff_cost: f64,
    /// The closed loop (momentum and 20 model rounds, in memory, noiseless) on a room that
    /// behaves like the uncut model, after as many captures: excess when the nodes hold the
    /// cut model and when they hold the uncut one. The camera's errors see every entry, so
    /// the loop recovers part of what the open-loop cut-off costs.
    pub loop_captures: usize,
    pub loop_excess_cut: f64,
    pub loop_excess_uncut: f64,
}

impl Sparsity {
    fn new(case: &str, cut: &Problem, uncut: &Problem, start: &[LinearRgb]) -> Result<Self> {
        let kept: usize = cut.columns().iter().map(|c| c.len()).sum();
        let nonzero: usize = uncut.columns().iter().map(|c| c.len()).sum();
        let (nodes, patches) = (cut.nodes(), cut.patches());
        let entry = 4 + 3 * 8;
        let best_cut = optimum(cut)?;
        let best_uncut = optimum(uncut)?;
        let loop_captures = 15;
        let closed = |model: &Problem| -> Result<f64> {
            let mut plant = Plant::new(uncut.clone(), PlantConfig::default())?;
            let config = LoopConfig {
                model_rounds: 20,
                ..LoopConfig::new(StepRule::Momentum { theta: 1.0 }, loop_captures)
            };
            let trace = closed_loop::run(model, &mut plant, start, &config)?;
            Ok(best_uncut.excess(plant.true_objective(&trace.shown, loop_captures)))
        };
        let s = Self {
            case: case.into(),
            nodes,
            patches,
            kept,
            nonzero,
            sparse_bytes: 2 * kept * entry,
            dense_bytes: 2 * nodes * patches * entry,
            cutoff_cost: best_uncut.excess(uncut.objective(&best_cut.x)),
            loop_captures,
            loop_excess_cut: closed(cut)?,
            loop_excess_uncut: closed(uncut)?,
        };
        println!("{}", s.line());
        Ok(s)
    }

    /// The sentence the terminal and the page print.
    pub fn line(&self) -> String {
        format!(
            "{}: model only what the scene needs: {} of {} non-zero attenuation entries kept ({:.1}%; {:.2}% of all {}×{}); {:.1} kB per round with supports against {:.1} kB with dense errors; the cut-off costs {:.1e} excess on the uncut model; in the closed loop ({} captures, momentum + 20 model rounds, the room behaving like the uncut model) {:.1e} with the cut model against {:.1e} with the uncut one",
            self.case,
            self.kept,
            self.nonzero,
            // nonzero is 0 only for a room without light: nothing kept of nothing.
            100.0 * self.kept as f64 / self.nonzero.max(1) as f64,
            100.0 * self.kept as f64 / (self.nodes * self.patches).max(1) as f64,
            self.nodes,
            self.patches,
            self.sparse_bytes as f64 / 1000.0,
            self.dense_bytes as f64 / 1000.0,
            self.cutoff_cost,
            self.loop_captures,
            self.loop_excess_cut,
            self.loop_excess_uncut,
        )
    }
}

pub(super) fn scene_sparsity(
    case: &str,
    cal: &pipeline::Calibrated,
    model: &pipeline::Model,
) -> Result<Sparsity> {
    let uncut = pipeline::uncut_problem(cal, model)?;
    Sparsity::new(case, &model.problem, &uncut, &model.conventional)
}

/// The synthetic room with its own 3σ cut-off against the same room with every entry the
/// generator writes.
pub(super) fn synthetic_sparsity(case: &str, nodes: usize, seed: u64) -> Result<Sparsity> {
    let room = synthetic_room(&SyntheticConfig::new(nodes, seed))?;
    let start = conventional_start(&room.problem, &room.charts, LinearRgb::splat(0.5))?;
    let cut = room.problem;
    let uncut = synthetic_room(&SyntheticConfig {
        cutoff_sigmas: 0.0,
        ..SyntheticConfig::new(nodes, seed)
    })?
    .problem;
    Sparsity::new(case, &cut, &uncut, &start)
}
