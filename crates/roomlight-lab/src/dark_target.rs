//! A dark target (issue 22, item 3): the light the luminaires throw on the projection-mapping
//! target enters the objective with a weight `w` ([`roomlight_calib::procedure::Target::with_dark`]:
//! target patches whose reference is the black level, rows scaled by `√w`), and what it costs
//! the room. For each weight the measured model's exact optimum ([`optimum`]) is rendered
//! noiselessly (the simulator's truth): the whole-room ΔE00 against the LEDs, and the light on
//! the target. The board's ANSI contrast under each optimum is measured by [`crate::pm`].
//! These are the model's optima, not rounds of the agents: what the rounds converge to within
//! 1% of `G*`, without their last percent.

use crate::pipeline::{Calibrated, FrameBuilder, Model};
use crate::whole_room::{Reach, ReachMap, WholeRoom, delta_e_map, white_luminance};
use anyhow::{Context, Result};
use roomlight_calib::charts::PatchSample;
use roomlight_core::LinearRgb;
use roomlight_core::metrics::luminance;
use roomlight_core::optimum::optimum;
use roomlight_sim::{Capture, Frame, Room};

/// The weights of the trade-off curve.
pub const WEIGHTS: [f64; 5] = [0.0, 0.1, 1.0, 10.0, 100.0];

/// The weight suggested where a dark target is asked for: a target patch counts as much as a
/// chart patch (the room has 4 of them against some 50 to 290 chart patches, so the target as a
/// whole weighs less than one chart). On the small room's quick demo it cut the light on the
/// target from 79% of the LEDs' to 36% without raising the whole-room ΔE00 (8.6 at w = 0,
/// 7.0 at w = 1); at 10 the room pays (12.1) for more contrast (docs/results.md).
pub const DEFAULT_WEIGHT: f64 = 1.0;

/// One point of the trade-off curve.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TradeoffPoint {
    pub weight: f64,
    /// The model's optimum at this weight, one value per node.
    #[serde(skip)]
    pub x: Vec<LinearRgb>,
    /// Whole-room ΔE00 (mean, 95th percentile over reached pixels) of the optimum's render
    /// against the LED preset's.
    pub room_de00_mean: f64,
    pub room_de00_p95: f64,
    /// Mean luminance on the target's camera pixels under the optimum, as a share of that
    /// under the LEDs (dark room subtracted from both).
    pub target_light_share: f64,
    /// The board's ANSI contrast under the optimum's projector lighting (filled by
    /// [`crate::pm`]; 0 until then).
    pub ansi_contrast: f64,
}

/// The trade-off curve on LED preset `preset` of `room`, measured as `lit` ([`crate::pipeline::measure_lit`]
/// on a calibration with target patches), at `weights`.
pub fn curve(
    room: &Room,
    cal: &Calibrated,
    reach: &ReachMap,
    preset: usize,
    lit: &[PatchSample],
    weights: &[f64],
) -> Result<Vec<TradeoffPoint>> {
    let yardstick = Yardstick::new(room, cal, reach, preset)?;
    weights
        .iter()
        .map(|&weight| {
            let model = Model::for_weight(cal, lit, weight)?;
            let best = optimum(&model.problem)
                .with_context(|| format!("the model's optimum at dark-target weight {weight}"))?;
            yardstick.point(weight, best.x)
        })
        .collect()
}

/// What the agents' rounds reached on the trade-off's preset at the weight they ran with,
/// measured as the curve's points are (noiseless render against the LEDs), with the charts'
/// ΔE00 of the rounds beside it.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RoundsPoint {
    #[serde(flatten)]
    pub point: TradeoffPoint,
    /// Mean over the chart patches of the rounds' ΔE00 (target and wall patches left out).
    pub charts_de00_mean: f64,
    /// Captures the rounds took.
    pub captures: u64,
}

/// The rounds' result `x` on preset `preset`, run at dark-target weight `weight`, measured as
/// [`curve`]'s points are; `charts_de00_mean` and `captures` are the run's.
#[allow(clippy::too_many_arguments)]
pub fn rounds_point(
    room: &Room,
    cal: &Calibrated,
    reach: &ReachMap,
    preset: usize,
    weight: f64,
    x: &[LinearRgb],
    charts_de00_mean: f64,
    captures: u64,
) -> Result<RoundsPoint> {
    let point = Yardstick::new(room, cal, reach, preset)?.point(weight, x.to_vec())?;
    Ok(RoundsPoint {
        point,
        charts_de00_mean,
        captures,
    })
}

/// [`rounds_point`] for a preset's outcome in the demo: its rounds' result, the weight its model
/// ran with, the mean of its charts' ΔE00.
pub fn rounds_of(
    room: &Room,
    cal: &Calibrated,
    reach: &ReachMap,
    preset: usize,
    outcome: &crate::report::PresetOutcome,
) -> Result<RoundsPoint> {
    let charts: Vec<f64> = outcome
        .result
        .de00
        .iter()
        .zip(&outcome.chart_of_patch)
        .filter(|(_, c)| c.is_some())
        .map(|(d, _)| *d)
        .collect();
    rounds_point(
        room,
        cal,
        reach,
        preset,
        outcome.dark_weight,
        &outcome.result.x,
        crate::report::mean(&charts),
        outcome.result.captures,
    )
}

/// Fills in the board's ANSI contrast under projector lighting from projection mapping's
/// measurements (the curve's optima, and the rounds' from the preset's own row), and prints
/// the curve and the rounds beside it.
pub fn with_ansi(d: &mut crate::report::DarkTarget, pm: &crate::pm::PmResult) {
    for (p, a) in d.points.iter_mut().zip(&pm.tradeoff_ansi) {
        p.ansi_contrast = *a;
    }
    let row = pm.ansi_by_preset.iter().find(|(n, _)| *n == d.preset);
    if let (Some(r), Some((_, a))) = (d.rounds.as_mut(), row) {
        r.point.ansi_contrast = a[2];
    }
    println!(
        "dark target on {}: ANSI contrast under the optimum's projector lighting {}",
        d.preset,
        d.points
            .iter()
            .map(|p| format!("w {}: {:.1}:1", p.weight, p.ansi_contrast))
            .collect::<Vec<_>>()
            .join(", ")
    );
    if let (Some(r), Some((_, a))) = (&d.rounds, row) {
        println!(
            "dark target on {}: the rounds at w {}: ANSI contrast dark {:.1} : LED {:.1} : projector lighting {:.1}; \
             whole-room ΔE00 mean {:.2}, p95 {:.2}; charts ΔE00 {:.2}; light on the target {:.0}% of the LEDs'; {} captures",
            d.preset,
            r.point.weight,
            a[0],
            a[1],
            a[2],
            r.point.room_de00_mean,
            r.point.room_de00_p95,
            r.charts_de00_mean,
            100.0 * r.point.target_light_share,
            r.captures
        );
    }
}

/// What a lighting is measured against: the dark room, the LED preset, and the target's pixels.
struct Yardstick<'a> {
    room: &'a Room,
    reach: &'a ReachMap,
    frames: FrameBuilder,
    dark: Capture,
    led: Capture,
    white: f64,
    target: Vec<bool>,
    led_light: f64,
}

impl<'a> Yardstick<'a> {
    fn new(room: &'a Room, cal: &Calibrated, reach: &'a ReachMap, preset: usize) -> Result<Self> {
        let dark_frames = vec![Frame::Black; room.projectors().len()];
        let dark = room.render(&dark_frames, None)?;
        let led = room.render(&dark_frames, Some(preset))?;
        let surface: Vec<bool> = reach.reach.iter().map(|r| *r != Reach::NoSurface).collect();
        let white = white_luminance(&led, &surface)?;
        let target: Vec<bool> = room.pixels().iter().map(|p| p.target).collect();
        let led_light = target_light(&led, &dark, &target)?;
        anyhow::ensure!(
            led_light > 0.0,
            "the LED preset puts no light on the target"
        );
        Ok(Self {
            room,
            reach,
            frames: FrameBuilder::new(room, &cal.regions, cal.responses.clone())?,
            dark,
            led,
            white,
            target,
            led_light,
        })
    }

    /// The luminaires at `x` (one value per node), rendered noiselessly.
    fn point(&self, weight: f64, x: Vec<LinearRgb>) -> Result<TradeoffPoint> {
        let result = self.room.render(&self.frames.frames(&x), None)?;
        let de = delta_e_map(&self.led, &result, self.white)?;
        let whole = WholeRoom::measure(&de, self.reach, self.white)?;
        Ok(TradeoffPoint {
            weight,
            room_de00_mean: whole.de00_mean,
            room_de00_p95: whole.de00_p95,
            target_light_share: target_light(&result, &self.dark, &self.target)? / self.led_light,
            ansi_contrast: 0.0,
            x,
        })
    }
}

/// Mean luminance over the `mask` pixels of `c` above the dark room's.
pub fn target_light(c: &Capture, dark: &Capture, mask: &[bool]) -> Result<f64> {
    let lum = |p: &[f32; 3]| luminance(LinearRgb(p.map(f64::from)));
    let values: Vec<f64> = c
        .pixels
        .iter()
        .zip(&dark.pixels)
        .zip(mask)
        .filter(|(_, m)| **m)
        .map(|((a, b), _)| lum(a) - lum(b))
        .collect();
    anyhow::ensure!(!values.is_empty(), "the target is not in the camera's view");
    Ok(values.iter().sum::<f64>() / values.len() as f64)
}

/// The preset the trade-off curve is measured on: the one named "paper" (matched to the
/// paper's contrasts), else the first.
pub fn preset(scene: &roomlight_sim::Scene) -> Option<usize> {
    scene
        .presets
        .iter()
        .position(|p| p.name == "paper")
        .or_else(|| (!scene.presets.is_empty()).then_some(0))
}
