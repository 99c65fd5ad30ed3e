//! The camera side of the loop (DESIGN §3.4): holds the current error vector, measured or
//! predicted from the nodes' contributions, computes `G`, and decides momentum restarts.

use crate::model::{ModelError, PatchId, check_len, validate_values};
use crate::rgb::LinearRgb;
use serde::{Deserialize, Serialize};

/// Whether a round's errors come from a capture or from the model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ErrorKind {
    /// From a camera capture.
    Measured,
    /// Predicted: the last errors minus the sum of the nodes' contribution changes.
    Predicted,
}

/// What the camera broadcasts with the errors of one round.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RoundSummary {
    /// Round number, counting measured and model rounds, starting at 1.
    pub round: u64,
    /// Measured or predicted.
    pub kind: ErrorKind,
    /// `G` of these errors.
    pub objective: f64,
    /// True when `G` rose over the previous round: momentum nodes restart.
    pub restart: bool,
}

/// The camera's error state.
#[derive(Debug, Clone)]
pub struct ErrorAggregator {
    errors: Vec<LinearRgb>,
    round: u64,
    last_objective: Option<f64>,
}

impl ErrorAggregator {
    /// An aggregator for a room of `patches` patches, before the first capture.
    pub fn new(patches: usize) -> Self {
        Self {
            errors: vec![LinearRgb::ZERO; patches],
            round: 0,
            last_objective: None,
        }
    }

    /// The current errors, one per patch.
    pub fn errors(&self) -> &[LinearRgb] {
        &self.errors
    }

    /// Gathers the errors on one node's support, in support order.
    pub fn errors_on(&self, support: &[PatchId]) -> Vec<LinearRgb> {
        support.iter().map(|&i| self.errors[i as usize]).collect()
    }

    /// Starts a measured round from captured errors `e = r − y`.
    pub fn measured(&mut self, errors: Vec<LinearRgb>) -> Result<RoundSummary, ModelError> {
        check_len("measured errors", errors.len(), self.errors.len())?;
        validate_values("measured errors", &errors, false)?;
        self.errors = errors;
        Ok(self.close_round(ErrorKind::Measured))
    }

    /// Subtracts one node's contribution change `δ_n` from the predicted errors.
    /// Rejected whole (nothing applied) if a patch is unknown or a value is not finite.
    pub fn add_contribution(
        &mut self,
        contribution: impl IntoIterator<Item = (PatchId, LinearRgb)>,
    ) -> Result<(), ModelError> {
        let items: Vec<(PatchId, LinearRgb)> = contribution.into_iter().collect();
        self.check_contribution(&items)?;
        self.apply_checked(&items);
        Ok(())
    }

    /// Whether [`Self::add_contribution`] would take `items`: every patch known, every value
    /// finite.
    pub fn check_contribution(&self, items: &[(PatchId, LinearRgb)]) -> Result<(), ModelError> {
        for (k, &(i, delta)) in items.iter().enumerate() {
            if i as usize >= self.errors.len() {
                return Err(ModelError::PatchOutOfRange {
                    what: "contribution",
                    patch: i,
                    patches: self.errors.len(),
                });
            }
            validate_values("contribution", &[delta], false).map_err(|e| match e {
                ModelError::NotFinite {
                    what,
                    channel,
                    value,
                    ..
                } => ModelError::NotFinite {
                    what,
                    index: k,
                    channel,
                    value,
                },
                other => other,
            })?;
        }
        Ok(())
    }

    /// Subtracts a contribution that [`Self::check_contribution`] accepted.
    pub(crate) fn apply_checked(&mut self, items: &[(PatchId, LinearRgb)]) {
        for &(i, delta) in items {
            self.errors[i as usize] -= delta;
        }
    }

    /// Closes a model round: the errors now held are the prediction `ê ← ê − Σ δ_n`.
    pub fn predicted(&mut self) -> RoundSummary {
        self.close_round(ErrorKind::Predicted)
    }

    fn close_round(&mut self, kind: ErrorKind) -> RoundSummary {
        self.round += 1;
        let objective = crate::metrics::objective(&self.errors);
        let restart = self.last_objective.is_some_and(|last| objective > last);
        self.last_objective = Some(objective);
        RoundSummary {
            round: self.round,
            kind,
            objective,
            restart,
        }
    }
}
