//! The lighting target through the charts and the model over it (DESIGN §3.1, §4.5): which
//! chart patches the model keeps (those measured in every capture: the black level, the
//! attenuation and the target lighting) and the problem on them. Written once for every
//! caller that turns captures into a model: the in-process pipeline, a camera agent that
//! surveys a room before any projector joins. It must not know how the captures were taken
//! (LEDs, projectors, processes).

use crate::CalibError;
use crate::charts::{PatchSample, PatchStatus};
use roomlight_core::{AttenuationColumn, LinearRgb, ModelError, PatchId, Problem};
use std::collections::HashMap;

/// The target lighting on the patches the model keeps.
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    /// Room patch index (into the charts' patches, chart by chart) of each model patch.
    pub patches: Vec<usize>,
    /// The room's black level on them (every projector black, the target lighting off).
    pub black: Vec<LinearRgb>,
    /// The target lighting's mean on them.
    pub target: Vec<LinearRgb>,
    /// Its standard error (the patch noise).
    pub noise: Vec<LinearRgb>,
}

impl Target {
    /// The target lighting `lit` over the room patches that are `usable` (measured in every
    /// other capture of the model) and that `lit` measured too; `black` is the black level of
    /// every room patch. No patch left is an error.
    pub fn new(
        black: &[LinearRgb],
        usable: &[bool],
        lit: &[PatchSample],
    ) -> Result<Self, CalibError> {
        if black.len() != lit.len() || usable.len() != lit.len() {
            return Err(CalibError::Invalid {
                field: "target",
                problem: format!(
                    "{} patches lit, {} black levels, {} usable flags",
                    lit.len(),
                    black.len(),
                    usable.len()
                ),
            });
        }
        let patches: Vec<usize> = (0..lit.len())
            .filter(|&i| usable[i] && lit[i].status == PatchStatus::Ok)
            .collect();
        if patches.is_empty() {
            return Err(CalibError::Invalid {
                field: "target",
                problem: "no chart patch could be measured in every capture".into(),
            });
        }
        Ok(Self {
            black: patches.iter().map(|&i| black[i]).collect(),
            target: patches.iter().map(|&i| lit[i].mean).collect(),
            noise: patches.iter().map(|&i| lit[i].std_error).collect(),
            patches,
        })
    }

    /// The same from a black capture's samples: patches it did not measure are left out.
    pub fn from_samples(black: &[PatchSample], lit: &[PatchSample]) -> Result<Self, CalibError> {
        let usable: Vec<bool> = black.iter().map(|s| s.status == PatchStatus::Ok).collect();
        let means: Vec<LinearRgb> = black.iter().map(|s| s.mean).collect();
        Self::new(&means, &usable, lit)
    }

    /// The model patch of each room patch it keeps.
    pub fn index(&self) -> HashMap<usize, PatchId> {
        self.patches
            .iter()
            .enumerate()
            .map(|(k, &i)| (i, k as PatchId))
            .collect()
    }

    /// Attenuation columns given over room patches (`(room patch, value)` per entry)
    /// restricted to the model's patches.
    pub fn columns(
        &self,
        columns: &[Vec<(u32, LinearRgb)>],
    ) -> Result<Vec<AttenuationColumn>, CalibError> {
        let index = self.index();
        columns
            .iter()
            .map(|c| {
                let (support, values): (Vec<PatchId>, Vec<LinearRgb>) = c
                    .iter()
                    .filter_map(|&(i, p)| index.get(&(i as usize)).map(|&k| (k, p)))
                    .unzip();
                AttenuationColumn::new(support, values).map_err(invalid)
            })
            .collect()
    }

    /// The problem with these columns (none for a room whose projectors have not joined yet).
    pub fn problem(&self, columns: Vec<AttenuationColumn>) -> Result<Problem, CalibError> {
        Problem::new(
            columns,
            self.black.clone(),
            self.target.clone(),
            self.noise.clone(),
        )
        .map_err(invalid)
    }

    /// Each chart's model patches, for `charts` charts of `per_chart` patches each.
    pub fn chart_patches(&self, charts: usize, per_chart: usize) -> Vec<Vec<PatchId>> {
        let index = self.index();
        (0..charts)
            .map(|m| {
                (0..per_chart)
                    .filter_map(|j| index.get(&(per_chart * m + j)).copied())
                    .collect()
            })
            .collect()
    }
}

fn invalid(e: ModelError) -> CalibError {
    CalibError::Invalid {
        field: "model",
        problem: e.to_string(),
    }
}
