//! What a room's installer configures once for calibration over the wire (DESIGN §4), and how
//! a photograph becomes the model's patches: the charts' patches, and with a dark target
//! (issue 22 item 3) patches on the projection-mapping target after them, whose light enters
//! the objective with a weight `w` ([`Target::with_dark`]: reference the black level, rows
//! scaled by `√w`). The scale is applied where camera pixels become patch values (each
//! capture's means here, each calibration column in `calibration`), so the rounds, the node
//! agents and the model file see one consistent weighted problem and need no change.

use roomlight_calib::CalibError;
use roomlight_calib::charts::{
    COLUMNS, ChartCorners, PatchSample, ROWS, SampleConfig, sample_charts, sample_region,
};
use roomlight_calib::image_io::LinearImage;
use roomlight_calib::procedure::{Setup, TARGET_PATCH_GRID, Target, target_patches};
use roomlight_core::{LinearRgb, Problem};

/// The dark-target weight a camera agent runs with unless its config names one: a target patch
/// counts as much as a chart patch (the lab's suggested weight, `roomlight_lab::dark_target`).
pub const DEFAULT_DARK_WEIGHT: f64 = 1.0;

/// Above this dark-target weight the camera agent warns that per-pixel shading fights it:
/// shading brightens, block by block, what the rounds dim to keep the target dark (its gains
/// reach whatever the LEDs' photograph asks, and that light reflects onto the target). On the
/// lab at 1 every preset settled after its 10 passes; at 10 the gains grew pass after pass to
/// 28, chart patches saturated and left the model one after another, and the rounds had not
/// settled minutes later (docs/results.md). 3 lies between the two and was not measured.
pub const SHADED_DARK_WEIGHT: f64 = 3.0;

/// The largest dark-target weight a survey takes: at 1000 a target patch's squared light
/// weighs as much as forty charts', far past where the room stops paying for contrast (the
/// lab's trade-off curve ends at 100, docs/results.md).
pub const MAX_DARK_WEIGHT: f64 = 1000.0;

/// The survey: where the charts are in the camera image, how to sample them, which camera
/// pixels are the target, and how dark the luminaires keep it.
#[derive(Debug, Clone)]
pub struct Survey {
    pub corners: Vec<ChartCorners>,
    pub sample: SampleConfig,
    /// The target's camera pixels (row-major, the camera's resolution): luminaires keep them
    /// dark.
    pub target_mask: Vec<bool>,
    /// Room patch index of each of the model's patches: chart · patches per chart + patch for
    /// the charts', then `charts · 24 + k` for target patch `k`.
    pub patches: Vec<usize>,
    /// The camera's resolution (the target mask's size).
    pub width: u32,
    pub height: u32,
    /// Camera pixels of each target patch ([`target_patches`] over the mask); empty when the
    /// dark weight is 0 (the model over the charts alone, as before).
    target_patches: Vec<Vec<u32>>,
    /// The weight of a target patch's squared light against a chart patch's.
    dark_weight: f64,
}

impl Survey {
    /// A survey of a `width × height` camera whose model patches are still to be chosen
    /// ([`Survey::with_patches`]). With `dark_weight` > 0 the target mask is split into up to
    /// [`TARGET_PATCH_GRID`]² patches measured beside the charts' and kept at the room's black
    /// level with that weight. A weight that is not finite or outside 0 to
    /// [`MAX_DARK_WEIGHT`], or a mask that is not `width × height`, is refused.
    pub fn new(
        corners: Vec<ChartCorners>,
        sample: SampleConfig,
        target_mask: Vec<bool>,
        (width, height): (u32, u32),
        dark_weight: f64,
    ) -> Result<Self, CalibError> {
        if !(dark_weight.is_finite() && (0.0..=MAX_DARK_WEIGHT).contains(&dark_weight)) {
            return Err(CalibError::Invalid {
                field: "dark_target_weight",
                problem: format!("is {dark_weight}, expected 0 to {MAX_DARK_WEIGHT}"),
            });
        }
        if target_mask.len() as u64 != u64::from(width) * u64::from(height) {
            return Err(CalibError::Invalid {
                field: "target_mask",
                problem: format!("{} pixels for a {width}×{height} camera", target_mask.len()),
            });
        }
        let target_patches = if dark_weight > 0.0 {
            target_patches(&target_mask, width, TARGET_PATCH_GRID)
        } else {
            Vec::new()
        };
        Ok(Self {
            corners,
            sample,
            target_mask,
            patches: Vec::new(),
            width,
            height,
            target_patches,
            dark_weight,
        })
    }

    /// The same survey over the model patches `patches` (room patch indices).
    pub fn with_patches(mut self, patches: Vec<usize>) -> Self {
        self.patches = patches;
        self
    }

    /// The weight of the light on the target ([`Survey::new`]).
    pub fn dark_weight(&self) -> f64 {
        self.dark_weight
    }

    /// How many room patches a photograph has: the charts', then the target's.
    pub fn room_patches(&self) -> usize {
        self.dark_patches().end
    }

    /// The room patches on the target.
    pub fn dark_patches(&self) -> std::ops::Range<usize> {
        let first = self.corners.len() * COLUMNS * ROWS;
        first..first + self.target_patches.len()
    }

    /// Whether room patch `room` is on the target (kept dark).
    pub fn is_dark(&self, room: usize) -> bool {
        self.dark_patches().contains(&room)
    }

    /// Whether model patch `k` (`patches[k]`) is on the target.
    pub fn kept_dark(&self, k: usize) -> bool {
        self.patches.get(k).is_some_and(|&r| self.is_dark(r))
    }

    /// The row scale of room patch `room`: `√w` on the target, 1 on the charts.
    pub fn scale(&self, room: usize) -> f64 {
        if self.is_dark(room) {
            self.dark_weight.sqrt()
        } else {
            1.0
        }
    }

    /// Every room patch of a photograph: the charts' patches chart by chart, then the target's.
    pub fn sample(&self, image: &LinearImage) -> Result<Vec<PatchSample>, CalibError> {
        let mut all = sample_charts(image, &self.corners, &self.sample)?;
        all.extend(
            self.target_patches
                .iter()
                .map(|r| sample_region(image, r, &self.sample)),
        );
        Ok(all)
    }

    /// The model's patches of a photograph's room patches (`samples`, [`Survey::sample`]):
    /// each one's mean scaled as its row is, and whether it was measured; an error when the
    /// survey names a patch the photograph does not have.
    pub fn measured(&self, samples: &[PatchSample]) -> Result<(Vec<LinearRgb>, Vec<bool>), String> {
        let mut means = Vec::with_capacity(self.patches.len());
        let mut ok = Vec::with_capacity(self.patches.len());
        for &i in &self.patches {
            let Some(sample) = samples.get(i) else {
                return Err(format!(
                    "the survey names patch {i}, the photograph has {}",
                    samples.len()
                ));
            };
            means.push(sample.mean * self.scale(i));
            ok.push(sample.status == roomlight_calib::charts::PatchStatus::Ok);
        }
        Ok((means, ok))
    }

    /// The model before any projector joins, from the room's patches with every projector dark
    /// and the LEDs off (`black`) and on (`lit`): the patches both measured, each chart patch's
    /// target the LEDs' light and each target patch's the black level, weighed
    /// ([`Target::with_dark`]). Returns the problem (no columns yet) and the survey over its
    /// patches.
    pub fn model(
        self,
        black: &[PatchSample],
        lit: &[PatchSample],
    ) -> Result<(Problem, Self), CalibError> {
        let target =
            Target::from_samples(black, lit)?.with_dark(self.dark_patches(), self.dark_weight)?;
        let problem = target.problem(Vec::new())?;
        Ok((problem, self.with_patches(target.patches)))
    }

    /// The calibration procedure's view of the survey: the charts and the target patches
    /// (sampled unscaled; `calibration` scales the columns).
    pub fn setup(&self) -> Setup {
        Setup {
            corners: self.corners.clone(),
            sample: self.sample,
            target_mask: self.target_mask.clone(),
            target_patches: self.target_patches.clone(),
            wall_patches: Vec::new(),
            reference: None,
        }
    }

    /// The model's patches on chart `chart` (for a node's conventional start).
    pub(super) fn chart_patches(&self, chart: usize) -> Vec<u32> {
        let per = COLUMNS * ROWS;
        self.patches
            .iter()
            .enumerate()
            .filter(|(_, i)| !self.is_dark(**i) && **i / per == chart)
            .map(|(k, _)| k as u32)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use roomlight_calib::charts::PatchStatus;

    fn sample(mean: f64) -> PatchSample {
        PatchSample {
            mean: LinearRgb::splat(mean),
            std_error: LinearRgb::splat(0.01),
            pixels: 50,
            status: PatchStatus::Ok,
        }
    }

    /// A 20 × 20 camera without charts and a 10 × 10 target.
    fn survey(weight: f64) -> Survey {
        let mask = (0..400u32)
            .map(|i| (4..14).contains(&(i % 20)) && (6..16).contains(&(i / 20)))
            .collect();
        Survey::new(Vec::new(), SampleConfig::default(), mask, (20, 20), weight).expect("survey")
    }

    #[test]
    fn a_dark_target_is_sampled_scaled_and_kept_at_the_black_level() {
        let plain = survey(0.0);
        assert_eq!(plain.room_patches(), 0, "weight 0: the charts alone");
        let dark = survey(4.0);
        assert_eq!(dark.dark_patches(), 0..4);
        assert!(dark.is_dark(3) && !dark.is_dark(4));
        assert!((dark.scale(0) - 2.0).abs() < 1e-12);
        // Each pixel's value is its column: the patches' means are their columns' means.
        let image = LinearImage {
            width: 20,
            height: 20,
            pixels: (0..400).map(|i| [(i % 20) as f32 / 100.0; 3]).collect(),
        };
        let samples = dark.sample(&image).expect("sampled");
        assert_eq!(samples.len(), 4);
        let dark = dark.with_patches(vec![1, 0]);
        let (means, ok) = dark.measured(&samples).expect("measured");
        assert_eq!(ok, vec![true, true]);
        for (m, i) in means.iter().zip([1, 0]) {
            let want = 2.0 * samples[i].mean[0];
            assert!((m[0] - want).abs() < 1e-12, "{} against {want}", m[0]);
        }
        let err = dark.clone().with_patches(vec![4]).measured(&samples);
        assert!(err.expect_err("no patch 4").contains("patch 4"));
        // The model: reference = black, everything × √4.
        let black: Vec<PatchSample> = (0..4).map(|_| sample(0.01)).collect();
        let lit: Vec<PatchSample> = (0..4).map(|_| sample(0.3)).collect();
        let (problem, with) = survey(4.0).model(&black, &lit).expect("model");
        assert_eq!(with.patches, vec![0, 1, 2, 3]);
        assert_eq!(problem.target()[2], LinearRgb::splat(0.02));
        assert_eq!(problem.black()[2], LinearRgb::splat(0.02));
        assert_eq!(problem.noise()[2], LinearRgb::splat(0.02));
    }

    #[test]
    fn a_survey_refuses_a_bad_weight_or_mask() {
        for bad in [-1.0, f64::NAN, f64::INFINITY, MAX_DARK_WEIGHT * 2.0] {
            let e = Survey::new(
                Vec::new(),
                SampleConfig::default(),
                vec![false; 4],
                (2, 2),
                bad,
            )
            .expect_err("refused")
            .to_string();
            assert!(e.contains("dark_target_weight"), "{e}");
        }
        let e = Survey::new(
            Vec::new(),
            SampleConfig::default(),
            vec![false; 3],
            (2, 2),
            1.0,
        )
        .expect_err("refused")
        .to_string();
        assert!(e.contains("target_mask") && e.contains("2×2"), "{e}");
    }
}
