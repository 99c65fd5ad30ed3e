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
        self.reweigh(dark, weight, true, "dark target weight")
    }

    /// The room patches in `walls` (the wall patches, [`super::Setup::wall_patch_range`]) kept
    /// with their target lighting, their squared errors weighed by `weight` (rows scaled by
    /// `√weight`); weight 0 leaves them out. A weight that is not finite or is negative is
    /// refused.
    pub fn with_walls(
        self,
        walls: std::ops::Range<usize>,
        weight: f64,
    ) -> Result<Self, CalibError> {
        self.reweigh(walls, weight, false, "wall weight")
    }

    /// The patches in `range` weighed by `weight` (0: left out), their reference the black
    /// level when `to_black`.
    fn reweigh(
        self,
        range: std::ops::Range<usize>,
        weight: f64,
        to_black: bool,
        field: &'static str,
    ) -> Result<Self, CalibError> {
        if !(weight.is_finite() && weight >= 0.0) {
            return Err(CalibError::Invalid {
                field,
                problem: format!("is {weight}, expected a finite weight >= 0"),
            });
        }
        let keep: Vec<bool> = self
            .patches
            .iter()
            .map(|i| weight > 0.0 || !range.contains(i))
            .collect();
        if keep.iter().all(|k| !k) {
            return Err(CalibError::Invalid {
                field: "target",
                problem: "no chart patch left beside the weighed patches".into(),
            });
        }
        let s = weight.sqrt();
        let mut out = Self::empty();
        for k in (0..self.patches.len()).filter(|&k| keep[k]) {
            let i = self.patches[k];
            let inside = range.contains(&i);
            out.patches.push(i);
            out.black.push(self.black[k]);
            out.target.push(if inside && to_black {
                self.black[k]
            } else {
                self.target[k]
            });
            out.noise.push(self.noise[k]);
            out.scale.push(if inside { s } else { self.scale[k] });
        }
        Ok(out)
    }

    fn empty() -> Self {
        Self {
            patches: Vec::new(),
            black: Vec::new(),
            target: Vec::new(),
            noise: Vec::new(),
            scale: Vec::new(),
        }
    }

    /// Without the patches in `range` that no column reaches (`columns` over room patches,
    /// [`Target::columns`]' input): no node changes their light, so they would only add a
    /// constant to `G` and hide the excess. Wall tiles in a shadow or outside every footprint
    /// go this way; the chart patches are never in `range`.
    pub fn without_unreached(
        self,
        range: std::ops::Range<usize>,
        columns: &[Vec<(u32, LinearRgb)>],
    ) -> Self {
        let mut reached = std::collections::HashSet::new();
        for c in columns {
            reached.extend(c.iter().map(|(i, _)| *i as usize));
        }
        let mut out = Self::empty();
        for k in 0..self.patches.len() {
            let i = self.patches[k];
            if range.contains(&i) && !reached.contains(&i) {
                continue;
            }
            out.patches.push(i);
            out.black.push(self.black[k]);
            out.target.push(self.target[k]);
            out.noise.push(self.noise[k]);
            out.scale.push(self.scale[k]);
        }
        out
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

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(v: f64) -> PatchSample {
        PatchSample {
            mean: LinearRgb::splat(v),
            std_error: LinearRgb::splat(0.01),
            pixels: 36,
            status: PatchStatus::Ok,
        }
    }

    /// Two chart patches, then two wall patches (room patches 2 and 3).
    fn four() -> Target {
        let lit: Vec<PatchSample> = [0.5, 0.6, 0.7, 0.8].map(sample).to_vec();
        Target::new(&[LinearRgb::splat(0.1); 4], &[true; 4], &lit).expect("target")
    }

    #[test]
    fn walls_keep_their_lighting_and_are_weighed() {
        let t = four().with_walls(2..4, 0.25).expect("walls");
        assert_eq!(t.patches, vec![0, 1, 2, 3]);
        assert_eq!(t.scale, vec![1.0, 1.0, 0.5, 0.5]);
        assert_eq!(t.target[3], LinearRgb::splat(0.8), "not sent to black");
        let dark = four().with_dark(2..4, 0.25).expect("dark");
        assert_eq!(
            dark.target[3],
            LinearRgb::splat(0.1),
            "a dark patch's reference is black"
        );
        let none = four().with_walls(2..4, 0.0).expect("weight 0");
        assert_eq!(none.patches, vec![0, 1]);
        assert!(four().with_walls(2..4, f64::NAN).is_err());
        assert!(four().with_walls(2..4, -1.0).is_err());
        assert!(four().with_walls(0..4, 0.0).is_err(), "nothing left");
    }

    #[test]
    fn walls_no_node_reaches_are_left_out_and_charts_never() {
        let columns = vec![
            vec![(0, LinearRgb::splat(0.2)), (3, LinearRgb::splat(0.1))],
            vec![(1, LinearRgb::splat(0.3))],
        ];
        let t = four()
            .with_walls(2..4, 1.0)
            .expect("walls")
            .without_unreached(2..4, &columns);
        assert_eq!(t.patches, vec![0, 1, 3], "wall 2 is lit by no node");
        assert_eq!(t.target.len(), 3);
        assert_eq!(t.scale.len(), 3);
        // A chart patch no node reaches stays (its error is the model's to report).
        let t = four().without_unreached(0..0, &[vec![(0, LinearRgb::splat(0.2))]]);
        assert_eq!(t.patches, vec![0, 1, 2, 3]);
        let problem = four()
            .with_walls(2..4, 1.0)
            .expect("walls")
            .without_unreached(2..4, &columns);
        let cols = problem.columns(&columns).expect("columns");
        assert_eq!(cols[0].support(), &[0, 2], "room patch 3 is model patch 2");
    }
}
