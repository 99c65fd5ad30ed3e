//! Per-node update rules (DESIGN §3.2–§3.4). A [`NodeState`] is what ONE node agent holds: its
//! own attenuation column, the white response `s` on its support, its displayed value and the
//! little state its rule needs. It sees nothing else of the room but the errors it is sent.

use crate::model::{AttenuationColumn, ModelError, PatchId, check_len, validate_values};
use crate::rgb::LinearRgb;
use serde::{Deserialize, Serialize};

/// The paper's fixed step, ε = 1e-5 with patch values and errors in 8-bit units (DESIGN §3.2).
/// In the unit scale used here (values in `[0, 1]`) that is `1e-5 · 255²` ≈ 0.65.
pub const PAPER_EPSILON: f64 = 1e-5 * 255.0 * 255.0;

/// How a node turns the errors it receives into its next value.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum StepRule {
    /// `x ← clip(x − ε g)` with one ε for every node (DESIGN §3.2). The paper's rule uses
    /// [`PAPER_EPSILON`]; the best global fixed step `1/λ_max(PᵀP)` per channel is only known
    /// to a central oracle (see [`crate::optimum::global_step`]).
    Fixed { epsilon: LinearRgb },
    /// The per-node safe step `ε_n = θ / h_n` with `h_n = (PᵀP·1)_n` (DESIGN §3.3).
    /// `0 < θ ≤ 1` decreases `G` monotonically with an exact plant; `θ < 2` converges.
    Safe { theta: f64 },
    /// Nesterov/FISTA momentum in the metric `diag(h_n/θ)`, with restarts on the camera's flag
    /// (DESIGN §3.4). The node shows the clipped extrapolated point.
    Momentum { theta: f64 },
}

impl StepRule {
    /// The paper's baseline rule.
    pub fn paper() -> Self {
        Self::Fixed {
            epsilon: LinearRgb::splat(PAPER_EPSILON),
        }
    }

    /// The safe step for errors `delay` captures stale: θ at 70% of the largest the delay rule
    /// allows, θ < 2 sin(π / (2(2τ + 1))) (τ = 0: 2, τ = 1: 1, τ = 2: 0.618), kept at most 1.
    /// The margin covers a measured model whose curvature bound falls short of the room's: at
    /// 90% the simulated small room still oscillated for ten captures with τ = 1 (its `h` is
    /// about 10% under the room's). Momentum and model rounds have no such guarantee with
    /// stale errors.
    pub fn safe_for_delay(delay: usize) -> Self {
        let tau = delay as f64;
        let allowed = 2.0 * (std::f64::consts::PI / (2.0 * (2.0 * tau + 1.0))).sin();
        Self::Safe {
            theta: (0.7 * allowed).min(1.0),
        }
    }

    /// Checks the parameters: ε finite and ≥ 0; θ in `(0, 2)`.
    pub fn validate(&self) -> Result<(), ModelError> {
        match *self {
            Self::Fixed { epsilon } => validate_values("fixed step epsilon", &[epsilon], true),
            Self::Safe { theta } | Self::Momentum { theta } => {
                if theta.is_finite() && theta > 0.0 && theta < 2.0 {
                    Ok(())
                } else {
                    Err(ModelError::Parameter {
                        what: "theta",
                        value: theta,
                        expected: "a number in (0, 2); (0, 1] for a guaranteed decrease",
                    })
                }
            }
        }
    }

    /// A short name for tables.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Fixed { .. } => "fixed",
            Self::Safe { .. } => "safe",
            Self::Momentum { .. } => "momentum",
        }
    }
}

/// One node's optimisation state. Holds only node-local information.
#[derive(Debug, Clone)]
pub struct NodeState {
    column: AttenuationColumn,
    /// `h_n = Σ_{i∈S_n} p_{n,i} s_i` per channel (DESIGN §3.3).
    curvature: LinearRgb,
    rule: StepRule,
    /// The value the projector shows (the clipped extrapolated point under momentum).
    shown: LinearRgb,
    /// The last plain projected-gradient point (momentum's `x_k`); equals `shown` otherwise.
    anchor: LinearRgb,
    /// FISTA's `t_k`; 1 right after a start or a restart.
    t: f64,
}

impl NodeState {
    /// Builds a node from its column, `s` on its support (same order), its rule, and the value
    /// it starts from (clipped into `[0, 1]`).
    pub fn new(
        column: AttenuationColumn,
        white_response: &[LinearRgb],
        rule: StepRule,
        start: LinearRgb,
    ) -> Result<Self, ModelError> {
        rule.validate()?;
        validate_values("start value", &[start], false)?;
        let mut node = Self {
            column,
            curvature: LinearRgb::ZERO,
            rule,
            shown: start.clamp_unit(),
            anchor: start.clamp_unit(),
            t: 1.0,
        };
        node.set_white_response(white_response)?;
        Ok(node)
    }

    /// Replaces `s` on the support (after a node joined or left, the camera rebroadcasts it).
    ///
    /// `s_i` can never be below the node's own `p_{n,i}` (it includes it); a measured `s` that
    /// is, through noise, is raised to `p_{n,i}` so that `h_n ≥ ‖p_n‖²` and the step stays safe.
    pub fn set_white_response(&mut self, white_response: &[LinearRgb]) -> Result<(), ModelError> {
        check_len(
            "white response on the support",
            white_response.len(),
            self.column.len(),
        )?;
        validate_values("white response on the support", white_response, true)?;
        let mut h = LinearRgb::ZERO;
        for (p, s) in self.column.values().iter().zip(white_response) {
            h += p.hadamard(p.zip(*s, f64::max));
        }
        self.curvature = h;
        Ok(())
    }

    /// The value the projector shows now.
    pub fn shown(&self) -> LinearRgb {
        self.shown
    }

    /// This node's attenuation column.
    pub fn column(&self) -> &AttenuationColumn {
        &self.column
    }

    /// `h_n` per channel.
    pub fn curvature(&self) -> LinearRgb {
        self.curvature
    }

    /// The rule this node follows.
    pub fn rule(&self) -> StepRule {
        self.rule
    }

    /// Forgets momentum (used when the node must hold or restart).
    pub fn reset_momentum(&mut self) {
        self.anchor = self.shown;
        self.t = 1.0;
    }

    /// Applies one round's errors `e` on the support (same order as the support), measured or
    /// predicted, and returns the change of the shown value `Δx_n`.
    ///
    /// Invalid errors (wrong length, NaN) are rejected and leave the state untouched. Channels
    /// where `h_n = 0` (empty or all-zero support) do not move: there is no information there.
    pub fn update(&mut self, errors: &[LinearRgb], restart: bool) -> Result<LinearRgb, ModelError> {
        check_len("errors on the support", errors.len(), self.column.len())?;
        validate_values("errors on the support", errors, false)?;
        // g_n = −Σ p_{n,i} e_i; the descent direction is −g = Σ p e.
        let mut descent = LinearRgb::ZERO;
        for (p, e) in self.column.values().iter().zip(errors) {
            descent += p.hadamard(*e);
        }
        let before = self.shown;
        match self.rule {
            StepRule::Fixed { epsilon } => {
                self.shown = (self.shown + epsilon.hadamard(descent)).clamp_unit();
                self.anchor = self.shown;
            }
            StepRule::Safe { theta } => {
                self.shown = (self.shown + self.safe_step(theta).hadamard(descent)).clamp_unit();
                self.anchor = self.shown;
            }
            StepRule::Momentum { theta } => {
                if restart {
                    self.t = 1.0;
                    self.anchor = self.shown;
                }
                // x_{k+1} = clip(y_k − D⁻¹∇G(y_k)), the gradient measured at the shown point.
                let next = (self.shown + self.safe_step(theta).hadamard(descent)).clamp_unit();
                let t_next = 0.5 * (1.0 + (1.0 + 4.0 * self.t * self.t).sqrt());
                let beta = (self.t - 1.0) / t_next;
                self.shown = (next + (next - self.anchor) * beta).clamp_unit();
                self.anchor = next;
                self.t = t_next;
            }
        }
        Ok(self.shown - before)
    }

    /// `θ / h_n` per channel; zero where `h_n = 0` (the node has nothing to learn from there).
    fn safe_step(&self, theta: f64) -> LinearRgb {
        self.curvature
            .map(|h| if h > 0.0 { theta / h } else { 0.0 })
    }

    /// The node's contribution change `δ_n = p_n Δx_n` on its support (DESIGN §3.4), as sent to
    /// the camera for model rounds.
    pub fn contribution(
        &self,
        delta_shown: LinearRgb,
    ) -> impl Iterator<Item = (PatchId, LinearRgb)> + '_ {
        self.column
            .iter()
            .map(move |(i, p)| (i, p.hadamard(delta_shown)))
    }
}
