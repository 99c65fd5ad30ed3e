//! The sequence of rounds ([`Controller`]): captures and model rounds, captures averaged with
//! the model's prediction, stale captures refused, the restart flag, and the settle rule.

use crate::aggregator::{ErrorAggregator, RoundSummary};
use crate::model::{ModelError, PatchId, check_len, validate_values};
use crate::rgb::LinearRgb;

/// What the next round is, as the [`Controller`] decides it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Next {
    /// Capture, and send the measured errors.
    Capture,
    /// Send errors predicted from the last round's contributions, without a capture.
    Model,
}

/// The sequence of rounds (DESIGN §3.4): a capture, then `model_rounds` model rounds whose
/// errors are the last ones minus the nodes' contributions (`ê ← ê − Σ δ_n`), then a capture
/// again. Each round's restart flag is set when `G` rose over the previous round (adaptive
/// restart) or when the live projectors changed since the last round (a projector that joins
/// starts its momentum afresh: a restart puts every node on the same momentum sequence again,
/// and the problem the momentum was built on is not the one now). Settling is judged on the
/// captures alone ([`Settle`]).
///
/// **Captures are averaged.** A capture's errors are fused with what the last ones predict for
/// it (the errors held, less the contributions since: the model's account of what the nodes
/// changed), per patch and channel by Kalman's gain: `e ← ê + (e_measured − ê)·g`,
/// `g = P⁻/(P⁻ + 1)`, `P` the variance of the errors held in units of the capture's σ² (1 after
/// a capture alone) and `P⁻ = P + α²·step²` with the model's error on the step since (below).
/// In a static room this is the plain average, `g = 1/k` after `k` captures, up to `average`
/// ([`AVERAGE_CAPTURES`] by default): the camera noise falls by `√k` (past the cap `P⁻` stays
/// at least `1/(average − 1)`, a gain of at least `1/average`, a moving average whose variance
/// is `1/(2·average − 1)` of a capture's: `1/15` at 8), and the noise the rounds would
/// otherwise fit (their floor) with it.
///
/// When the capture disagrees with the prediction beyond its noise (a χ² of the difference over
/// its variance more than [`INNOVATION_SIGMAS`] standard deviations above its degrees of
/// freedom), the model's prediction of the step is taken to be off by a share `α` of the step
/// itself, `α²` estimated from the difference's squares beyond the noise over the step's; the
/// patches the step moved most then follow the capture, those it left alone keep their
/// average. (Before, such a capture started the average afresh: on the lab's paper preset the
/// first large step always did, which cost a capture to 1%.) The average starts afresh (`P = 1`,
/// the capture alone) at the first capture, when the live projectors or the target changed,
/// and when even that model error does not explain the difference or would exceed
/// [`MODEL_ERROR_LIMIT`] (a room that changed, a late frame). With no noise known (every σ
/// zero) there is nothing to judge by, and every capture stands alone.
///
/// **Stale captures are refused.** A camera that hands over its frames late shows, after the
/// nodes stepped, the room as it was before: [`Controller::stale`] tells such a capture by the
/// same χ² (it disagrees with the prediction and agrees with the last capture), and the caller
/// takes another instead of stepping the nodes twice on errors they already answered.
///
/// Drive it as: `match next() { Capture => measured(errors), Model => predicted() }` (a capture
/// for which `stale(errors)` holds is dropped and another taken), send the
/// round's errors, hand it each contribution ([`Controller::contribution`]); repeat.
///
/// A round's contributions are summed in a fixed order, not in the order they arrived:
/// floating-point addition is not associative, and over the wire the order is the network's
/// and the scheduler's, so the same room would otherwise predict errors that differ in their
/// last bits from run to run — and, a few hundred rounds later, take a different number of
/// captures.
#[derive(Debug, Clone)]
pub struct Controller {
    aggregator: ErrorAggregator,
    /// The contributions of the round sent last, checked, not yet subtracted.
    contributions: Vec<Vec<(PatchId, LinearRgb)>>,
    /// The per-patch noise `σ` of the captures, for the settle rule.
    noise: Vec<LinearRgb>,
    model_rounds: usize,
    /// The most captures averaged ([`Controller`]; 1: none).
    average: usize,
    /// Captures in the current average (0 before the first).
    averaged: usize,
    /// The errors of the last capture as averaged: what the room showed then, before the nodes
    /// stepped (empty before the first capture).
    held: Vec<LinearRgb>,
    /// The variance of the errors held, per patch and channel, in units of the capture's σ²
    /// (1 after a capture alone, `1/k` after `k` averaged; empty before the first).
    variance: Vec<[f64; 3]>,
    /// Captures judged stale in a row since the last one measured.
    stale_run: usize,
    /// Model rounds still to run before the next capture.
    pending: usize,
    /// The generation of the live projectors the last round was sent to.
    generation: Option<u64>,
    /// The live projectors changed since the last round: the next one restarts.
    changed: bool,
    settle: Settle,
}

impl Controller {
    /// A controller for a room of `noise.len()` patches whose captures have noise `σ` per
    /// patch, running `model_rounds` model rounds after each capture.
    pub fn new(noise: Vec<LinearRgb>, model_rounds: usize) -> Self {
        Self {
            aggregator: ErrorAggregator::new(noise.len()),
            contributions: Vec::new(),
            noise,
            model_rounds,
            average: AVERAGE_CAPTURES,
            averaged: 0,
            held: Vec::new(),
            variance: Vec::new(),
            stale_run: 0,
            pending: 0,
            generation: None,
            changed: false,
            settle: Settle::default(),
        }
    }

    /// The same, averaging up to `captures` captures (at least 1: 1 takes every capture
    /// alone).
    pub fn averaging(self, captures: usize) -> Self {
        Self {
            average: captures.max(1),
            ..self
        }
    }

    /// What the next round is: a model round while some remain after the last capture, else
    /// a capture.
    pub fn next(&self) -> Next {
        if self.pending > 0 {
            Next::Model
        } else {
            Next::Capture
        }
    }

    /// The live projectors are at `generation` (see [`Projectors::generation`](super::Projectors::generation); any count that
    /// changes whenever a projector enters or leaves the rounds): when it differs from the
    /// one the last round saw, the next round restarts. The first generation seen is no change.
    pub fn live(&mut self, generation: u64) {
        if self.generation.is_some_and(|g| g != generation) {
            self.changed = true;
        }
        self.generation = Some(generation);
    }

    /// A capture measured `errors = r − y` (one per patch): the measured round to send. Model
    /// rounds follow it, and the settle rule takes its `G`. Refused (nothing changes) when the
    /// errors have the wrong length or a value that is not finite.
    pub fn measured(&mut self, errors: Vec<LinearRgb>) -> Result<RoundSummary, ModelError> {
        check_len("measured errors", errors.len(), self.noise.len())?;
        validate_values("measured errors", &errors, false)?;
        // The capture measured what the contributions changed: they are the prediction it is
        // averaged with.
        self.apply_contributions();
        let errors = self.averaged_with_prediction(errors);
        self.held.clone_from(&errors);
        self.stale_run = 0;
        let mut summary = self.aggregator.measured(errors)?;
        let noise = objective_noise(self.aggregator.errors(), &self.noise);
        self.settle.observe(summary.objective, noise);
        self.pending = self.model_rounds;
        summary.restart |= std::mem::take(&mut self.changed);
        Ok(summary)
    }

    /// `measured` fused with the errors held (the prediction for this capture), see
    /// [`Controller`]; `measured` alone when the average starts afresh.
    fn averaged_with_prediction(&mut self, measured: Vec<LinearRgb>) -> Vec<LinearRgb> {
        let fresh = |this: &mut Self, measured: Vec<LinearRgb>| {
            this.variance = vec![[1.0; 3]; measured.len()];
            this.averaged = 1;
            measured
        };
        if self.changed || self.averaged == 0 || self.average <= 1 {
            return fresh(self, measured);
        }
        let predicted = self.aggregator.errors();
        // The model's error on the step since the last capture, as a share `α` of what it
        // predicted the step changed (`held − predicted`), when the capture disagrees with the
        // prediction beyond the noise: a large step whose prediction is off by a few percent.
        let model_error = match self.agrees(&measured, predicted, None) {
            Some(true) => None,
            None => return fresh(self, measured),
            Some(false) => match self.model_error(&measured) {
                Some(alpha2) => Some(alpha2),
                None => return fresh(self, measured),
            },
        };
        let predicted = self.aggregator.errors();
        let floor = 1.0 / (self.average - 1) as f64;
        let mut fused = Vec::with_capacity(measured.len());
        for (i, (p, m)) in predicted.iter().zip(&measured).enumerate() {
            let mut e = *p;
            for c in 0..3 {
                let s = self.noise[i][c];
                if s <= 0.0 {
                    e[c] = m[c];
                    continue;
                }
                let step = (self.held[i][c] - p[c]) / s;
                let q = model_error.map_or(0.0, |a2| a2 * step * step);
                let prior = self.variance[i][c] + q;
                // Kalman's gain: the prediction's variance over the difference's (σ² units),
                // the prediction's taken at least `floor` (a gain of at least 1/average).
                let gain = prior.max(floor) / (prior.max(floor) + 1.0);
                e[c] = p[c] + (m[c] - p[c]) * gain;
                // The fused errors' variance for that gain (Joseph's form: `gain` itself at
                // the optimal gain, less where the floor raised it: 1/15 at a gain of 1/8).
                self.variance[i][c] = (1.0 - gain).powi(2) * prior + gain * gain;
            }
            fused.push(e);
        }
        // The captures an average of equal weights would take to this noise: Σσ²/Σ(σ²·p).
        let (mut total, mut left) = (0.0, 0.0);
        for (v, s) in self.variance.iter().zip(&self.noise) {
            for c in 0..3 {
                total += s[c] * s[c];
                left += s[c] * s[c] * v[c];
            }
        }
        // No noise known (total 0): the capture alone, as above. Past the cap, a moving average
        // of gain 1/average leaves the noise of 2·average − 1 captures.
        self.averaged = if left > 0.0 {
            ((total / left).round() as usize).clamp(1, 2 * self.average - 1)
        } else {
            1
        };
        fused
    }

    /// `α²`, the model's relative error on the step since the last capture, estimated from
    /// how far `measured` lies from the prediction beyond the noise (the difference's squares
    /// less their expected noise, over the step's squares, each in units of σ²), when the
    /// prediction with that error agrees with the capture and `α` is at most
    /// [`MODEL_ERROR_LIMIT`]; `None` otherwise (the room changed in a way the step does not
    /// explain, or nothing stepped): the capture then starts the average afresh.
    fn model_error(&self, measured: &[LinearRgb]) -> Option<f64> {
        let predicted = self.aggregator.errors();
        let (mut excess, mut steps) = (0.0, 0.0);
        for (i, (p, m)) in predicted.iter().zip(measured).enumerate() {
            for c in 0..3 {
                let s = self.noise[i][c];
                if s > 0.0 {
                    let d = (m[c] - p[c]) / s;
                    let step = (self.held[i][c] - p[c]) / s;
                    excess += d * d - (1.0 + self.variance[i][c]);
                    steps += step * step;
                }
            }
        }
        // Nothing stepped (steps 0): no model error explains the difference.
        let alpha2 = excess.max(0.0) / steps;
        if !alpha2.is_finite() || alpha2 > MODEL_ERROR_LIMIT * MODEL_ERROR_LIMIT {
            return None;
        }
        (self.agrees(measured, predicted, Some(alpha2)) == Some(true)).then_some(alpha2)
    }

    /// Whether `measured` agrees with `expected` within the noise: the χ² of the difference
    /// over its variance (the capture's σ², the average's `σ²·p`, and with `model_error = α²`
    /// the model's `α²·step²`) at most [`INNOVATION_SIGMAS`] of its standard deviations above
    /// its degrees of freedom. A patch or channel of σ 0 cannot be judged and is left out;
    /// `None` when none can be (no noise known) or the χ² is not finite.
    fn agrees(
        &self,
        measured: &[LinearRgb],
        expected: &[LinearRgb],
        model_error: Option<f64>,
    ) -> Option<bool> {
        let (mut chi2, mut dof) = (0.0, 0usize);
        for (i, (m, p)) in measured.iter().zip(expected).enumerate() {
            for c in 0..3 {
                let s = self.noise[i][c];
                if s > 0.0 {
                    let d = (m[c] - p[c]) / s;
                    let held = self.variance.get(i).map_or(0.0, |v| v[c]);
                    let q = model_error.map_or(0.0, |a2| {
                        let step = (self.held[i][c] - p[c]) / s;
                        a2 * step * step
                    });
                    chi2 += d * d / (1.0 + held + q);
                    dof += 1;
                }
            }
        }
        let dof_f = dof as f64;
        let limit = dof_f + INNOVATION_SIGMAS * (2.0 * dof_f).sqrt();
        (dof > 0 && chi2.is_finite()).then_some(chi2 <= limit)
    }

    /// True when a capture shows the room as it was at the last capture, before the nodes
    /// stepped, rather than as they have shown since: it disagrees with the prediction beyond
    /// its noise and agrees with the errors of the last capture within it. A camera that hands
    /// over its frames late (its latency unknown, or longer than configured) gives such
    /// captures; acting on them steps the nodes a second time on errors they already answered,
    /// which diverges (`bench room --hard`'s stale cases). Refuse the capture and take another.
    ///
    /// Judged only between two measured rounds of the same live projectors and target, with
    /// some noise known, and at most [`STALE_CAPTURES`] times in a row: a room where the nodes'
    /// steps truly change nothing (a display that shows nothing) is measured again after
    /// that, rather than never. Nothing changes but the count of stale captures in a row.
    pub fn stale(&mut self, errors: &[LinearRgb]) -> bool {
        if self.changed
            || self.averaged == 0
            || self.stale_run >= STALE_CAPTURES
            || errors.len() != self.held.len()
        {
            return false;
        }
        self.apply_contributions();
        let stale = self.agrees(errors, self.aggregator.errors(), None) == Some(false)
            && self.agrees(errors, &self.held, None) == Some(true);
        if stale {
            self.stale_run += 1;
        }
        stale
    }

    /// The next model round (errors predicted from the contributions since the last round),
    /// or `None` when a capture is due instead.
    pub fn predicted(&mut self) -> Option<RoundSummary> {
        if self.next() != Next::Model {
            return None;
        }
        self.pending -= 1;
        self.apply_contributions();
        let mut summary = self.aggregator.predicted();
        summary.restart |= std::mem::take(&mut self.changed);
        Some(summary)
    }

    /// The target changed (another LED preset): the next round is a capture, it restarts the
    /// momentum, and settling is judged afresh.
    pub fn retarget(&mut self) {
        self.pending = 0;
        self.changed = true;
        self.settle = Settle::default();
    }

    /// One node's contribution change `δ_n` to the round just sent: the predicted errors lose
    /// it. Refused whole (nothing applied) if a patch is unknown or a value is not finite.
    /// Contributions are subtracted when the errors are next asked for, in an order that
    /// depends only on what they are (see [`Controller`]).
    pub fn contribution(
        &mut self,
        delta: impl IntoIterator<Item = (PatchId, LinearRgb)>,
    ) -> Result<(), ModelError> {
        let items: Vec<(PatchId, LinearRgb)> = delta.into_iter().collect();
        self.aggregator.check_contribution(&items)?;
        self.contributions.push(items);
        Ok(())
    }

    /// Subtracts the pending contributions in their canonical order: by patch ids, then by the
    /// values' bits (a total order on the contributions themselves, so the sum is the same
    /// whatever order they arrived in; equal contributions are interchangeable).
    fn apply_contributions(&mut self) {
        if self.contributions.is_empty() {
            return;
        }
        let mut pending = std::mem::take(&mut self.contributions);
        let key =
            |&(i, v): &(PatchId, LinearRgb)| (i, v[0].to_bits(), v[1].to_bits(), v[2].to_bits());
        pending.sort_unstable_by(|a, b| a.iter().map(key).cmp(b.iter().map(key)));
        for items in &pending {
            self.aggregator.apply_checked(items);
        }
        // The allocation is kept for the next round.
        pending.clear();
        self.contributions = pending;
    }

    /// The errors of the last round (measured, less the contributions since), one per patch.
    pub fn errors(&mut self) -> &[LinearRgb] {
        self.apply_contributions();
        self.aggregator.errors()
    }

    /// The measured `G` has settled at its noise (see [`Settle`]).
    pub fn settled(&self) -> bool {
        self.settle.settled()
    }

    /// How many captures the errors of the last capture average (1: that capture alone; 0
    /// before the first): the captures of equal weight that would leave the same noise,
    /// `Σσ²/Σσ²P`, rounded, where patches were fused with different gains or past the cap
    /// (the moving average's `2·average − 1`, at most). Their `G` carries about `½ Σ σ²/k` of
    /// camera noise, not `½ Σ σ²`.
    pub fn averaged(&self) -> usize {
        self.averaged
    }

    /// A capture has been taken: [`Controller::errors`] describe the room.
    pub fn has_measured(&self) -> bool {
        self.settle.measured()
    }
}

/// The most captures a [`Controller`] averages by default.
pub const AVERAGE_CAPTURES: usize = 8;

/// The most captures in a row [`Controller::stale`] refuses as stale: a camera up to this many
/// frames late is caught without being told its latency (a longer one is configured,
/// `stale_frames`).
pub const STALE_CAPTURES: usize = 3;

/// The largest relative error of the model's prediction of a step that a capture is still
/// averaged with (see [`Controller`]); beyond it the room changed in a way the step does not
/// explain and the average starts afresh.
pub const MODEL_ERROR_LIMIT: f64 = 0.5;

/// How many standard deviations of its χ² a capture's difference from the prediction may lie
/// above its mean and still be averaged ([`Controller`]).
pub const INNOVATION_SIGMAS: f64 = 4.0;

/// First-order standard deviation of a measured `G` from the patch noise:
/// `sqrt(Σ_i Σ_c (e_ic σ_ic)²)` (the settle rule's noise).
pub fn objective_noise(errors: &[LinearRgb], noise: &[LinearRgb]) -> f64 {
    errors
        .iter()
        .zip(noise)
        .map(|(e, s)| e.hadamard(*s).norm_squared())
        .sum::<f64>()
        .sqrt()
}

/// The settle rule (DESIGN §3.6): the measured `G` moved less than its noise, 3√2 σ_G (the
/// standard deviation of a difference of two noisy `G`s is √2 σ_G; three of them), over each of
/// the last two captures. With a noiseless camera `G` must stop changing to rounding (a relative
/// 1e-12). Further rounds only chase camera noise.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Settle {
    previous: Option<f64>,
    quiet: u32,
}

impl Settle {
    /// Captures running that must be quiet.
    pub const QUIET_CAPTURES: u32 = 2;

    /// A new capture measured `objective` with standard deviation `noise` (see
    /// `closed_loop::objective_noise`); true when the room has settled.
    pub fn observe(&mut self, objective: f64, noise: f64) -> bool {
        self.quiet = match self.previous {
            Some(g)
                if (objective - g).abs()
                    <= (3.0 * std::f64::consts::SQRT_2 * noise).max(1e-12 * objective.max(g)) =>
            {
                self.quiet + 1
            }
            _ => 0,
        };
        self.previous = Some(objective);
        self.settled()
    }

    /// The last captures were quiet.
    pub fn settled(&self) -> bool {
        self.quiet >= Self::QUIET_CAPTURES
    }

    /// A capture has been observed.
    pub fn measured(&self) -> bool {
        self.previous.is_some()
    }
}
