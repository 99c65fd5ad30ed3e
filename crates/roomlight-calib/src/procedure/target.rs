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
    /// Each model patch's row scale: 1 on chart patches, `√w` on the target patches kept dark
    /// with weight `w` ([`Target::with_dark`]). The problem, its columns and what the camera
    /// measures on the patch are all multiplied by it, so `G` weighs the patch's squared error
    /// by `w` and the core needs no change.
    pub scale: Vec<f64>,
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
            scale: vec![1.0; patches.len()],
            patches,
        })
    }

    /// The room patches in `dark` (the target patches, [`super::Setup::target_patch_range`])
    /// asked to stay at the black level, their squared errors weighed by `weight`: their
    /// reference becomes their black level (no luminaire light, whatever the LEDs gave them)
    /// and their rows are scaled by `√weight`. Weight 0 leaves them out: the model is the one
    /// over the chart patches alone. A weight that is not finite or is negative is refused.
    pub fn with_dark(self, dark: std::ops::Range<usize>, weight: f64) -> Result<Self, CalibError> {
        if !(weight.is_finite() && weight >= 0.0) {
            return Err(CalibError::Invalid {
                field: "dark target weight",
                problem: format!("is {weight}, expected a finite weight >= 0"),
            });
        }
        let keep: Vec<bool> = self
            .patches
            .iter()
            .map(|i| weight > 0.0 || !dark.contains(i))
            .collect();
        if keep.iter().all(|k| !k) {
            return Err(CalibError::Invalid {
                field: "target",
                problem: "no chart patch left beside the target patches".into(),
            });
        }
        let s = weight.sqrt();
        let mut out = Self {
            patches: Vec::new(),
            black: Vec::new(),
            target: Vec::new(),
            noise: Vec::new(),
            scale: Vec::new(),
        };
        for k in (0..self.patches.len()).filter(|&k| keep[k]) {
            let i = self.patches[k];
            let on_target = dark.contains(&i);
            out.patches.push(i);
            out.black.push(self.black[k]);
            out.target.push(if on_target {
                self.black[k]
            } else {
                self.target[k]
            });
            out.noise.push(self.noise[k]);
            out.scale.push(if on_target { s } else { self.scale[k] });
        }
        Ok(out)
    }

    /// Values measured on the model's patches, scaled as the model's rows are.
    pub fn scaled(&self, values: &[LinearRgb]) -> Vec<LinearRgb> {
        values
            .iter()
            .zip(&self.scale)
            .map(|(v, s)| *v * *s)
            .collect()
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
                    .filter_map(|&(i, p)| {
                        index
                            .get(&(i as usize))
                            .map(|&k| (k, p * self.scale[k as usize]))
                    })
                    .unzip();
                AttenuationColumn::new(support, values).map_err(invalid)
            })
            .collect()
    }

    /// The problem with these columns (none for a room whose projectors have not joined yet).
    pub fn problem(&self, columns: Vec<AttenuationColumn>) -> Result<Problem, CalibError> {
        Problem::new(
            columns,
            self.scaled(&self.black),
            self.scaled(&self.target),
            self.scaled(&self.noise),
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
