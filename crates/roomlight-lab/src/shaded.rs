//! Per-pixel shading on top of the rounds' result (issue 22 item 2), in process: what each
//! luminaire's light becomes when it follows the LEDs' photograph pixel by pixel and channel by
//! channel ([`roomlight_calib::shading`]), beside what the nodes alone reached.
//!
//! Everything the passes read is what a real room gives: the preset's LED photograph and the
//! dark room as the camera took them (noisy), the projectors' light captured through the same
//! noise, and each luminaire's decode from calibration. Only the figures are ground truth
//! (noiseless renders compared pixel by pixel with the LEDs', as the report's maps are). The
//! passes run here after the demo's rounds, on the in-process calibration; the agents run the
//! same passes over the wire (`roomlight_agent::camera`'s shading, `roomlight bench shading`).
//! The rounds' captures to 1% are those of the nodes alone, and each pass is one capture more.
//!
//! Only standard luminaires are shaded: a large aperture's pixels light a blurred disc each, so
//! gains per block of them would have to undo the blur (ill-posed); it keeps its node's light.
//! What shading cannot do: light beyond a projector's share of a blend (where one projector of
//! an overlap is at full light, the other's weight there is 0), and keep the target as dark as
//! a preset's dark-target weight made the rounds keep it (the target's pixels are left out of
//! the ratios, so light reflected onto it from a brighter room is nobody's error).

use crate::dark_target::target_light;
use crate::pipeline::{Calibrated, FrameBuilder, image};
use crate::whole_room::{Reach, ReachMap, WholeRoom, delta_e_map, map_image, white_luminance};
use anyhow::{Context, Result, ensure};
use roomlight_calib::charts::{COLUMNS, PatchStatus, ROWS};
use roomlight_calib::response::Response;
use roomlight_calib::shading::{self, Gains, Photographs, ratios};
use roomlight_core::LinearRgb;
use roomlight_core::metrics::patch_delta_e;
use roomlight_sim::{CameraNoise, Capture, Frame, Room};
use std::path::Path;

/// Passes after the rounds: on the lab the whole room's mean is within 3 ΔE00 of the LEDs
/// after four, and the fifth and sixth still take 0.1–0.4 off it (docs/results.md).
pub const PASSES: usize = 6;

/// Each pass moves a gain by this power of its measured ratio: inter-reflection makes a full
/// step overshoot where neighbours rise together.
pub const RATE: f64 = 0.8;

/// The room after some passes, against the LEDs.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Pass {
    /// Captures the passes took so far.
    pub captures: usize,
    pub whole_room_de00_mean: f64,
    pub whole_room_de00_p95: f64,
    /// The seam metric ([`crate::whole_room::Seam::excess_de00`]), if there are overlaps.
    pub seam_excess_de00: Option<f64>,
    /// Mean ΔE00 over the chart patches measured in both images.
    pub chart_de00_mean: f64,
    /// The light on the projection-mapping target, a share of the LEDs' there
    /// ([`crate::dark_target::target_light`]; `None` when the LEDs put none on it).
    pub target_light_share: Option<f64>,
}

/// The passes' path, the first being the rounds' result as the nodes left it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Shaded {
    pub rate: f64,
    /// Never empty: only [`shade`] makes one, and it records the rounds' result first.
    passes: Vec<Pass>,
    /// Per luminaire shaded: its name and the 5th and 95th percentiles of its gains at the end.
    pub gains: Vec<(String, f32, f32)>,
    /// The gains after the last pass, per room projector (`None`: not shaded).
    #[serde(skip)]
    pub final_gains: Vec<Option<Gains>>,
    /// The ΔE00 map after the last pass ([`crate::whole_room::map_image`]).
    #[serde(skip)]
    pub map: image::RgbImage,
    /// Where the report wrote it (relative to the report).
    pub map_file: Option<String>,
}

impl Shaded {
    /// The rounds' result, then each pass.
    pub fn passes(&self) -> &[Pass] {
        &self.passes
    }

    /// The rounds' result, before any pass.
    pub fn first(&self) -> &Pass {
        &self.passes[0]
    }

    /// After the last pass.
    pub fn last(&self) -> &Pass {
        &self.passes[self.passes.len() - 1]
    }
}

impl Shaded {
    /// One line: the whole room pass by pass, the charts and the light on the target before
    /// and after.
    pub fn summary(&self) -> String {
        let path: Vec<String> = self
            .passes
            .iter()
            .map(|p| {
                format!(
                    "{:.2} / {:.2}",
                    p.whole_room_de00_mean, p.whole_room_de00_p95
                )
            })
            .collect();
        let (first, last) = (self.first(), self.last());
        let target = |p: &Pass| {
            p.target_light_share
                .map_or("—".to_string(), |t| format!("{:.0}%", 100.0 * t))
        };
        format!(
            "per-pixel shading after the rounds (in process, {} captures): whole room ΔE00 mean / p95 {}; charts {:.2} → {:.2}; light on the target {} → {} of the LEDs'",
            last.captures,
            path.join(" → "),
            first.chart_de00_mean,
            last.chart_de00_mean,
            target(first),
            target(last)
        )
    }

    /// Writes the map after the last pass into the report folder `dir` as
    /// `<slug>-de00-map-shaded.png` and records its name.
    pub fn write_map(&mut self, dir: &Path, preset: &str) -> Result<()> {
        let file = format!(
            "{}-de00-map-shaded.png",
            crate::report::pictures::slug(preset)
        );
        crate::report::png::write_srgb8_image(&dir.join(&file), &self.map)?;
        self.map_file = Some(file);
        Ok(())
    }
}

/// Seed of the passes' camera noise, mixed with the run's.
const SEED: u64 = 0x5ade;

/// The camera the passes photograph with: a noise stream of its own (the rounds' captures
/// stay those of the nodes alone, capture for capture) and its photograph of the dark room.
#[derive(Debug)]
pub struct Camera {
    noise: CameraNoise,
    dark: Capture,
}

impl Camera {
    /// For runs seeded `seed`; takes the dark room's photograph (one capture).
    pub fn new(room: &Room, seed: u64) -> Result<Self> {
        let mut noise = CameraNoise::with_seed(room, seed ^ SEED);
        let black = vec![Frame::Black; room.projectors().len()];
        let dark = noise.expose(&room.render(&black, None)?);
        Ok(Self { noise, dark })
    }

    /// [`PASSES`] passes of [`shade`] on preset `index`, its LEDs photographed as `reference`.
    pub fn shade(
        &mut self,
        lab: (&Room, &Calibrated, &ReachMap),
        index: usize,
        reference: &Capture,
        x: &[LinearRgb],
    ) -> Result<Shaded> {
        let (room, cal, reach) = lab;
        let preset = Preset {
            index,
            reference,
            dark: &self.dark,
        };
        shade(room, cal, reach, preset, x, &mut self.noise, PASSES)
    }
}

/// The preset shaded and the camera's photographs the passes compare with: its LEDs alone
/// and the dark room, both as taken (noisy).
#[derive(Debug, Clone, Copy)]
pub struct Preset<'a> {
    pub index: usize,
    pub reference: &'a Capture,
    pub dark: &'a Capture,
}

/// `passes` passes of per-pixel shading on node values `x` (the rounds' result) for `preset`:
/// each captures the room (through `noise`), steps every decoded luminaire's gains towards the
/// photograph, and the room is measured against the LEDs' noiseless light.
pub fn shade(
    room: &Room,
    cal: &Calibrated,
    reach: &ReachMap,
    preset: Preset<'_>,
    x: &[LinearRgb],
    noise: &mut CameraNoise,
    passes: usize,
) -> Result<Shaded> {
    let frames = FrameBuilder::new(room, &cal.regions, cal.responses.clone())?;
    let black = vec![Frame::Black; room.projectors().len()];
    let truth = room.render(&black, Some(preset.index))?;
    let surface: Vec<bool> = reach.reach.iter().map(|r| *r != Reach::NoSurface).collect();
    let white = white_luminance(&truth, &surface)?;
    let charts = cal.corners.len() * COLUMNS * ROWS;
    let measured = |c: &Capture| -> Result<Vec<Option<LinearRgb>>> {
        Ok(cal
            .sample_room(c)?
            .into_iter()
            .take(charts)
            .map(|s| (s.status == PatchStatus::Ok).then_some(s.mean))
            .collect())
    };
    let led = measured(&truth)?;
    let dark_truth = room.render(&black, None)?;
    let on_target: Vec<bool> = room.pixels().iter().map(|p| p.target).collect();
    let led_on_target = target_light(&truth, &dark_truth, &on_target)?;
    let mut gains: Vec<Option<Gains>> = vec![None; room.projectors().len()];
    let mut decodes = Vec::new();
    for m in cal.measured.iter().filter(|m| m.projector.blends()) {
        let k = room.projector(&m.projector.id)?;
        let pinhole = &room.projectors()[k].pinhole;
        let size = (m.corr.projector_width, m.corr.projector_height);
        ensure!(
            size == (pinhole.width, pinhole.height),
            "{}: decoded as {}×{}, the projector is {}×{}",
            m.projector.id,
            size.0,
            size.1,
            pinhole.width,
            pinhole.height
        );
        gains[k] = Gains::flat(size.0, size.1);
        decodes.push((k, &m.corr));
    }
    let figures = |gains: &[Option<Gains>], captures: usize| -> Result<(Pass, Vec<f64>)> {
        let lit = room.render(&frames.frames_shaded(x, gains), None)?;
        let de = delta_e_map(&truth, &lit, white)?;
        let whole = WholeRoom::measure(&de, reach, white)?;
        let (target, got): (Vec<LinearRgb>, Vec<LinearRgb>) = led
            .iter()
            .zip(measured(&lit)?)
            .filter_map(|(a, b)| Some(((*a)?, b?)))
            .unzip();
        let pass = Pass {
            captures,
            whole_room_de00_mean: whole.de00_mean,
            whole_room_de00_p95: whole.de00_p95,
            seam_excess_de00: whole.seam.map(|s| s.excess_de00),
            chart_de00_mean: patch_delta_e(&target, &got)
                .context("the charts after shading")?
                .mean,
            // No LED light on the target: no share to give.
            target_light_share: (led_on_target > 0.0)
                .then(|| target_light(&lit, &dark_truth, &on_target))
                .transpose()?
                .map(|l| l / led_on_target),
        };
        Ok((pass, de))
    };
    let setup = cal.setup();
    let (reference, dark) = (image(preset.reference), image(preset.dark));
    // The nodes' light as the rounds left it: no floor, no gains.
    let (first, mut de) = figures(&[], 0)?;
    let mut path = vec![first];
    for pass in 1..=passes {
        let drawn = frames.frames_shaded(x, &gains);
        let current = image(&noise.expose(&room.render(&drawn, None)?));
        let photographs = Photographs {
            reference: &reference,
            current: &current,
            dark: &dark,
            excluded: &setup.target_mask,
            saturation: setup.sample.saturation,
        };
        let white = shading::white(&photographs);
        for &(k, corr) in &decodes {
            let r = ratios(&photographs, corr)?.relative_to(white);
            let room = headroom_of(&drawn[k], cal.responses.get(k));
            if let Some(g) = gains[k].as_mut() {
                g.step_within(&r, RATE, room.as_deref())?;
            }
        }
        let (next, map) = figures(&gains, pass)?;
        path.push(next);
        de = map;
    }
    Ok(Shaded {
        rate: RATE,
        passes: path,
        map: map_image(&de, reach)?,
        map_file: None,
        gains: decodes
            .iter()
            .filter_map(|&(k, _)| {
                let g = gains[k].as_ref()?;
                let (lo, hi) = g.spread();
                Some((room.projectors()[k].name.clone(), lo, hi))
            })
            .collect(),
        final_gains: gains,
    })
}

/// Per block of a drawn frame, the headroom of its light ([`shading::headroom`]): each code
/// turned back into its light through the projector's measured `response` (linear without).
fn headroom_of(frame: &Frame, response: Option<&Response>) -> Option<Vec<[f64; 3]>> {
    let Frame::Image(image) = frame else {
        return None;
    };
    let linear = Response::linear();
    let response = response.unwrap_or(&linear);
    let shares: Vec<[f64; 3]> = image
        .pixels
        .iter()
        .map(|code| response.to_share(*code).0)
        .collect();
    shading::headroom(&shares, image.width, image.height)
}
