//! The live model the camera agent holds while it runs: attenuation and `s`, which projectors
//! are still to be measured, each node's start, the assignments and claims of projectors
//! segmented over the wire, and the patches left out. It knows nothing of peers or the network:
//! it builds message bodies and writes its file, and callers decide whom to send them to.

use super::{RoomModel, Survey};
use crate::hardware::Assignment;
use roomlight_core::{AttenuationColumn, LinearRgb, ModelError, Problem};
use roomlight_proto::convert::{to_rgb, to_sparse};
use roomlight_proto::v1;
use std::collections::{HashMap, HashSet};

/// What hot calibration changes: the attenuation and `s`, and which projectors are still to be
/// measured.
pub(super) struct Live {
    pub(super) problem: Problem,
    pub(super) white: Vec<LinearRgb>,
    pub(super) uncalibrated: HashSet<String>,
    /// Projector id → its node ids (grows as projectors are segmented over the wire).
    pub(super) owners: HashMap<String, Vec<u32>>,
    /// Each node's start (`None`: the node agent's own default).
    pub(super) start: Vec<Option<LinearRgb>>,
    /// The weights and responses of the projectors segmented over the wire.
    pub(super) assignments: HashMap<String, Assignment>,
    /// Per projector segmented over the wire (standard, lighting a chart): the share of the
    /// light it gives each camera pixel, which projectors segmented later leave to it.
    pub(super) claims: HashMap<String, Vec<f32>>,
    /// The chart of each node segmented over the wire (for its conventional start).
    pub(super) charts: HashMap<u32, usize>,
    /// Patches some projector's light made unmeasurable during its calibration over the wire
    /// (saturated, or crossed by an edge): no column covers them, their target is their black
    /// level, and their measured errors are taken as zero.
    pub(super) excluded: Vec<bool>,
}

impl Live {
    /// The live model at start-up from the configured one.
    pub(super) fn new(model: &RoomModel) -> Self {
        // Nothing is known of a hot projector until it is measured: not its light in `s`, not
        // its columns.
        let unknown: Vec<usize> = model
            .hot
            .iter()
            .filter_map(|id| model.owners.get(id))
            .flatten()
            .map(|&n| n as usize)
            .collect();
        let problem = model.problem.without_nodes(&unknown);
        let white = problem.white_response();
        // A model resumed over the wire keeps its left-out patches: uncovered, target = black
        // (a dark target's patches are that by design: a capture that cannot measure one
        // leaves it out again).
        let excluded: Vec<bool> = (0..problem.patches())
            .map(|i| {
                model
                    .survey
                    .as_ref()
                    .is_some_and(|s| i < s.patches.len() && !s.kept_dark(i))
                    && problem.target()[i] == problem.black()[i]
                    && problem
                        .columns()
                        .iter()
                        .all(|c| c.get(i as u32) == LinearRgb::ZERO)
            })
            .collect();
        let start = match &model.start {
            Some(v) => v.iter().copied().map(Some).collect(),
            None => vec![None; problem.nodes()],
        };
        Self {
            problem,
            white,
            uncalibrated: model.hot.clone(),
            owners: model.owners.clone(),
            start,
            assignments: HashMap::new(),
            claims: HashMap::new(),
            charts: HashMap::new(),
            excluded,
        }
    }

    /// Each of `nodes`' attenuation, `s` on its support and start, as message bodies.
    pub(super) fn attenuation_bodies(&self, nodes: &[u32]) -> Vec<v1::room_message::Body> {
        nodes
            .iter()
            .filter_map(|&n| {
                let column = self.problem.columns().get(n as usize)?;
                let s = self
                    .problem
                    .white_response_on_support(&self.white, n as usize);
                Some(v1::room_message::Body::Attenuation(v1::Attenuation {
                    node: n,
                    p: Some(to_sparse(column.support(), column.values())),
                    s: Some(to_sparse(column.support(), &s)),
                    start: self
                        .start
                        .get(n as usize)
                        .copied()
                        .flatten()
                        .filter(|x| x.is_finite())
                        .map(|x| to_rgb(x.clamp_unit())),
                }))
            })
            .collect()
    }

    /// Patches a capture could not measure (`ok` false) that are not yet left out.
    pub(super) fn newly_unmeasurable(&self, ok: &[bool]) -> Vec<usize> {
        (0..ok.len())
            .filter(|&i| !ok[i] && !self.excluded.get(i).copied().unwrap_or(true))
            .collect()
    }

    /// Leaves `newly` out of the model for good, with these columns; `s` follows.
    pub(super) fn leave_out_with(
        &mut self,
        newly: &[usize],
        columns: Vec<AttenuationColumn>,
    ) -> Result<(), ModelError> {
        let problem = leave_out(&mut self.excluded, newly, columns, &self.problem)?;
        self.white = problem.white_response();
        self.problem = problem;
        Ok(())
    }

    /// The errors `r − y` of a capture, zero on the patches left out.
    pub(super) fn errors(&self, y: &[LinearRgb]) -> Vec<LinearRgb> {
        self.problem
            .target()
            .iter()
            .zip(y)
            .zip(&self.excluded)
            .map(|((r, y), &out)| if out { LinearRgb::ZERO } else { *r - *y })
            .collect()
    }

    /// Writes the live model as JSON through a temporary file beside `path`.
    pub(super) fn write(
        &self,
        survey: Option<&Survey>,
        path: &std::path::Path,
    ) -> std::io::Result<()> {
        let text = serde_json::to_string(&serde_json::json!({
            "problem": self.problem,
            "owners": self.owners,
            // Only when every node has one (else the node agents' own).
            "start": self.start.iter().copied().collect::<Option<Vec<LinearRgb>>>(),
            // Calibrated over the wire: the room patch of each model patch, so that a camera
            // agent restarted with the same survey resumes this model.
            "patches": survey.map(|s| &s.patches),
            // Its target patches' rows are scaled by this weight's root: a restarted camera
            // agent resumes the model at it, whatever its config asks.
            "dark_target_weight": survey.map(Survey::dark_weight),
        }))?;
        let tmp = path.with_extension("tmp");
        std::fs::write(&tmp, text)?;
        std::fs::rename(&tmp, path)
    }
}

/// The values of `nodes` (new, dark) that best fill the room's current errors `e` with the
/// other nodes held: `argmin ‖e − P_new x‖²` over `x ∈ [0, 1]`, per channel, solved exactly
/// as a problem of its own (target `max(e, 0)`, black `max(−e, 0)`, so that target − black = e).
pub(super) fn joining_start(
    problem: &Problem,
    nodes: &[u32],
    e: &[LinearRgb],
) -> Result<Vec<LinearRgb>, String> {
    let columns = nodes
        .iter()
        .filter_map(|&n| problem.columns().get(n as usize).cloned())
        .collect();
    let sub = Problem::new(
        columns,
        e.iter().map(|v| v.map(|c| (-c).max(0.0))).collect(),
        e.iter().map(|v| v.map(|c| c.max(0.0))).collect(),
        problem.noise().to_vec(),
    )
    .map_err(|e| e.to_string())?;
    Ok(roomlight_core::optimum::optimum(&sub)
        .map_err(|e| e.to_string())?
        .x
        .into_iter()
        .map(LinearRgb::clamp_unit)
        .collect())
}

/// Leaves `newly` out of the model for good (marked in `excluded`): every one of `columns`
/// loses them and their target becomes their black level; the problem with `columns`.
fn leave_out(
    excluded: &mut [bool],
    newly: &[usize],
    mut columns: Vec<AttenuationColumn>,
    problem: &Problem,
) -> Result<Problem, ModelError> {
    for &i in newly {
        if let Some(x) = excluded.get_mut(i) {
            *x = true;
        }
    }
    let target: Vec<LinearRgb> = problem
        .target()
        .iter()
        .zip(problem.black())
        .zip(excluded.iter())
        .map(|((t, b), &out)| if out { *b } else { *t })
        .collect();
    if !newly.is_empty() {
        for column in &mut columns {
            let (support, values): (Vec<u32>, Vec<LinearRgb>) = column
                .iter()
                .filter(|(i, _)| !excluded.get(*i as usize).copied().unwrap_or(true))
                .unzip();
            *column = AttenuationColumn::new(support, values)?;
        }
    }
    Problem::new(
        columns,
        problem.black().to_vec(),
        target,
        problem.noise().to_vec(),
    )
}
