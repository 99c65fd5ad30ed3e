//! The conventional start (DESIGN §3.1): radiometric compensation that ignores inter-reflection.
//! Each node fits its own chart alone:
//! `x_n = clip( Σ_{i∈C_n} p_{n,i}(r_i − d_i) / Σ_{i∈C_n} p_{n,i}² )`.

use crate::model::{AttenuationColumn, ModelError, PatchId, Problem};
use crate::rgb::LinearRgb;

/// The conventional value of one node from its column and its own chart `C_n`.
///
/// `target` and `black` are indexed by patch. Where the denominator is zero on a channel (no
/// chart in view, or the chart sees nothing of the node) that channel takes `fallback`: the
/// method has no information there, and the lights stay on rather than go black.
pub fn conventional_value(
    column: &AttenuationColumn,
    own_chart: &[PatchId],
    target: &[LinearRgb],
    black: &[LinearRgb],
    fallback: LinearRgb,
) -> Result<LinearRgb, ModelError> {
    let mut num = LinearRgb::ZERO;
    let mut den = LinearRgb::ZERO;
    for &i in own_chart {
        let idx = i as usize;
        if idx >= target.len() || idx >= black.len() {
            return Err(ModelError::PatchOutOfRange {
                what: "own chart",
                patch: i,
                patches: target.len().min(black.len()),
            });
        }
        let p = column.get(i);
        num += p.hadamard(target[idx] - black[idx]);
        den += p.hadamard(p);
    }
    let mut x = LinearRgb::ZERO;
    for c in 0..3 {
        x[c] = if den[c] > 0.0 {
            (num[c] / den[c]).clamp(0.0, 1.0)
        } else {
            fallback[c].clamp(0.0, 1.0)
        };
    }
    Ok(x)
}

/// The conventional start of every node; `charts[n]` is node `n`'s own chart.
pub fn conventional_start(
    problem: &Problem,
    charts: &[Vec<PatchId>],
    fallback: LinearRgb,
) -> Result<Vec<LinearRgb>, ModelError> {
    crate::model::check_len("own charts", charts.len(), problem.nodes())?;
    problem
        .columns()
        .iter()
        .zip(charts)
        .map(|(column, chart)| {
            conventional_value(column, chart, problem.target(), problem.black(), fallback)
        })
        .collect()
}
