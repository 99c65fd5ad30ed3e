//! Calibration of the simulated room from captures, through the one calibration procedure
//! ([`roomlight_calib::procedure`]) on the room as a rig ([`SimRig`]): what the demo, the
//! process commands and the benches start from. It owns turning the procedure's result into
//! the simulator's terms (node regions, room projector indices) and the lines it reports; the
//! order of captures and what each shows are the procedure's, the same as over the wire.

use anyhow::{Context, Result, bail};
use roomlight_calib::attenuation::{Attenuation, SUPPORT_SIGMAS};
use roomlight_calib::charts::ChartCorners;
use roomlight_calib::charts::PatchSample;
use roomlight_calib::procedure::Target;
use roomlight_calib::procedure::shape::Shape;
use roomlight_calib::procedure::{
    BringUp, Event, Layout, Measured, Placed, Procedure, Settings, Setup, Stage, WallTiling,
    place_calibrated, wall_exclusion, wall_patches,
};
use roomlight_calib::response::Response;
use roomlight_calib::rig::block_on;
use roomlight_core::LinearRgb;
use roomlight_core::conventional::conventional_value;
use roomlight_sim::{CameraNoise, Frame, NodeRegion, Room};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;

use super::*;

/// What calibration measured once for the room, whatever the lighting target.
#[derive(Debug)]
pub struct Calibrated {
    /// Each node's projector and weights (for the simulated hardware); node `n` is region `n`.
    pub regions: Vec<NodeRegion>,
    /// Each node's own chart (room chart index).
    pub node_charts: Vec<Option<usize>>,
    /// The charts' corners in the camera image.
    pub corners: Vec<ChartCorners>,
    /// Attenuation, black level and which patches it could measure.
    pub attenuation: Attenuation,
    /// Attenuation columns (entries within [`SUPPORT_SIGMAS`] σ of zero dropped, the target's
    /// patches whole: [`Attenuation::columns_whole_on`]), over every room patch.
    pub columns: Vec<Vec<(u32, LinearRgb)>>,
    /// Captures used.
    pub captures: usize,
    /// Each room projector's measured response (linear for those not calibrated).
    pub responses: Vec<Response>,
    /// The luminaires as the procedure measured them (decoded, response fitted), in room order.
    pub measured: Vec<Measured>,
    /// Weight of each wall patch's squared error in the models built from this calibration
    /// ([`Target::with_walls`]; a chart patch weighs 1, 0 leaves the walls out).
    pub wall_weight: f64,
    /// The projectors whose nodes blend with others' (a claim on the camera pixels, not a
    /// whole-frame node), each with its pixels kept black for the target: what the partition
    /// of unity is checked over ([`super::calibrated_partition`]).
    pub(crate) blending: Vec<(String, Vec<bool>)>,
    /// How each luminaire's nodes were shaped to the room's reference (none: flat), so that
    /// nodes placed again are shaped the same ([`Calibrated::regions_with_mask`]).
    shapes: HashMap<String, Shape>,
    /// The room as configured by hand, and how the procedure measured it.
    setup: Setup,
    settings: Settings,
}

impl Calibrated {
    /// Projector name → its node ids.
    pub fn owners(&self, room: &Room) -> HashMap<String, Vec<u32>> {
        let mut owners: HashMap<String, Vec<u32>> = HashMap::new();
        for (n, r) in self.regions.iter().enumerate() {
            owners
                .entry(room.projectors()[r.projector].name.clone())
                .or_default()
                .push(n as u32);
        }
        owners
    }

    /// The same nodes with another target kept dark (`mask`: camera pixels of the new target),
    /// e.g. a contrast board put where the bust was: the procedure places the measured
    /// projectors again. Fails if the nodes would change.
    pub fn regions_with_mask(&self, room: &Room, mask: &[bool]) -> Result<Vec<NodeRegion>> {
        self.placed_again(room, mask, true)
    }

    /// The nodes' blend: their weights before shaping ([`Nodes::ShapedTo`]), which is what
    /// sums to one across overlaps; the regions themselves when the nodes are flat.
    pub fn blend_regions(&self, room: &Room) -> Result<Vec<NodeRegion>> {
        if self.shapes.is_empty() {
            return Ok(self.regions.clone());
        }
        self.placed_again(room, &self.setup.target_mask, false)
    }

    /// The measured projectors placed again with `mask` as the target, shaped as they were
    /// when `shaped`. Fails if the nodes would change.
    fn placed_again(&self, room: &Room, mask: &[bool], shaped: bool) -> Result<Vec<NodeRegion>> {
        let setup = Setup {
            target_mask: mask.to_vec(),
            ..self.setup.clone()
        };
        let mut placed =
            place_calibrated(&setup, &self.measured, None, 0, &self.settings, &mut |_| {})?;
        for p in placed.iter_mut().filter(|_| shaped) {
            if let Some(shape) = self.shapes.get(&p.projector.id) {
                shape.apply(p)?;
            }
        }
        let (regions, charts) = regions(room, &placed)?;
        if charts != self.node_charts {
            bail!(
                "the new target changes the nodes ({} instead of {}); recalibrate",
                charts.len(),
                self.node_charts.len()
            );
        }
        Ok(regions)
    }

    /// The room patches on the target (empty unless calibrated with target patches).
    pub fn target_patch_range(&self) -> std::ops::Range<usize> {
        self.setup.target_patch_range()
    }

    /// The room patches on the walls, beyond the charts and the target.
    pub fn wall_patch_range(&self) -> std::ops::Range<usize> {
        self.setup.wall_patch_range()
    }

    /// The room as configured, with the patches calibration measured.
    pub fn setup(&self) -> &Setup {
        &self.setup
    }

    /// Every room patch of a capture, as calibration sampled them.
    pub fn sample_room(&self, capture: &roomlight_sim::Capture) -> Result<Vec<PatchSample>> {
        Ok(self.setup.sample_room(&image(capture))?)
    }

    /// The procedure's bring-up in the simulator's terms.
    fn new(room: &Room, mut setup: Setup, settings: Settings, up: BringUp) -> Result<Self> {
        // The photograph has shaped the nodes; nothing later reads it (nodes placed again
        // take the shapes kept, [`Calibrated::regions_with_mask`]).
        setup.reference = None;
        let (regions, node_charts) = regions(room, &up.placed)?;
        let blending = up
            .placed
            .iter()
            .filter(|p| p.claim.is_some())
            .map(|p| (p.projector.id.clone(), p.excluded.clone()))
            .collect();
        let shapes = up
            .placed
            .iter()
            .filter_map(|p| Some((p.projector.id.clone(), p.shape.clone()?)))
            .collect();
        let mut responses = vec![Response::linear(); room.projectors().len()];
        for m in &up.measured {
            responses[room.projector(&m.projector.id)?] = m.response.clone();
        }
        let attenuation = up.columns.attenuation;
        let columns = attenuation
            .columns_whole_on(SUPPORT_SIGMAS, setup.target_patch_range())?
            .iter()
            .map(|c| c.iter().collect())
            .collect();
        Ok(Self {
            regions,
            node_charts,
            corners: setup.corners.clone(),
            attenuation,
            columns,
            captures: up.captures,
            responses,
            measured: up.measured,
            wall_weight: 0.0,
            blending,
            shapes,
            setup,
            settings,
        })
    }
}

/// Placed projectors' nodes as node regions of room projectors, with each node's chart, in
/// node id order (the procedure numbers them from 0 in the order placed).
fn regions(room: &Room, placed: &[Placed]) -> Result<(Vec<NodeRegion>, Vec<Option<usize>>)> {
    let mut out = Vec::new();
    for p in placed {
        let projector = room.projector(&p.projector.id)?;
        for node in &p.nodes {
            if node.id as usize != out.len() {
                bail!(
                    "node ids are not numbered in order: {} at {}",
                    node.id,
                    out.len()
                );
            }
            out.push((
                NodeRegion {
                    projector,
                    weights: node.weights.clone(),
                },
                node.chart,
            ));
        }
    }
    Ok(out.into_iter().unzip())
}

pub use roomlight_calib::procedure::TARGET_PATCH_GRID;

/// Weight of a wall patch's squared error against a chart patch's when the walls are asked
/// for (issue 22 item 2; the lab has some 770 wall tiles its nodes reach, against 312 chart
/// patches). [`Calibrated::wall_weight`] starts at 0: the model over the charts, as before.
pub const WALL_WEIGHT: f64 = 0.25;

/// The room as configured by hand: the charts' corners, how they are sampled, the target;
/// with `target_patches`, patches on the target measured beside the charts' (so that a dark
/// target can be weighed in the objective, [`Model::for_weight`]); and tiles of the walls
/// beyond them ([`WallTiling::default`]), so that the model can ask for the LEDs' light over
/// the whole room.
pub fn setup(room: &Room, target_patches: bool) -> Result<Setup> {
    let target_mask: Vec<bool> = room.pixels().iter().map(|p| p.target).collect();
    let [width, height] = room.scene().camera.resolution;
    let patches = if target_patches {
        roomlight_calib::procedure::target_patches(&target_mask, width, TARGET_PATCH_GRID)
    } else {
        Vec::new()
    };
    let corners = chart_corners(room)?;
    let tiling = WallTiling::default();
    let exclude = wall_exclusion(&corners, &target_mask, width, tiling.margin);
    Ok(Setup {
        wall_patches: wall_patches(width, height, &exclude, &tiling),
        reference: None,
        corners,
        sample: sample_config(room),
        target_mask,
        target_patches: patches,
    })
}

/// Brings `room` up from dark through the one calibration procedure on the simulated room
/// (captures exposed through `noise`): structured light, responses, nodes and attenuation.
/// Progress goes to `bar`; `say` gets one line per stage.
pub fn calibrate(
    room: &Room,
    noise: &mut CameraNoise,
    bar: &indicatif::ProgressBar,
    say: impl FnMut(String),
) -> Result<Calibrated> {
    calibrate_with(room, false, noise, bar, say)
}

/// [`calibrate`], with `target_patches` measuring patches on the target too (through the same
/// attenuation captures; the chart patches' values are the same either way).
pub fn calibrate_with(
    room: &Room,
    target_patches: bool,
    noise: &mut CameraNoise,
    bar: &indicatif::ProgressBar,
    say: impl FnMut(String),
) -> Result<Calibrated> {
    calibrate_configured(
        room,
        target_patches,
        Settings::default(),
        Nodes::default(),
        noise,
        bar,
        say,
    )
}

/// How the luminaires' nodes drive their regions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Nodes {
    /// Evenly: one colour over the region, feathered.
    Flat,
    /// Following LED preset `n`'s falloff, photographed once with the projectors dark
    /// ([`roomlight_calib::procedure::shape`]).
    ShapedTo(usize),
}

impl Default for Nodes {
    /// Flat. Shaped to its first LED preset, the lab's whole-room ΔE00 mean fell on every
    /// preset, but the small room's mean and 95th percentile rose (docs/results.md): not the default.
    fn default() -> Self {
        Self::Flat
    }
}

/// Seed of the reference photograph's camera noise ([`Nodes::ShapedTo`]).
const REFERENCE_SEED: u64 = 0x5EED_0F1E;

/// [`calibrate_with`] with the procedure's `settings`, the nodes drawn as `nodes` says.
pub fn calibrate_configured(
    room: &Room,
    target_patches: bool,
    settings: Settings,
    nodes: Nodes,
    noise: &mut CameraNoise,
    bar: &indicatif::ProgressBar,
    mut say: impl FnMut(String),
) -> Result<Calibrated> {
    let mut setup = setup(room, target_patches)?;
    // The survey's photograph of the room under its own lighting, projectors dark: one
    // capture, counted with calibration's.
    let reference = match nodes {
        Nodes::Flat => 0,
        Nodes::ShapedTo(preset) => {
            let frames = vec![Frame::Black; room.projectors().len()];
            let lit = room.render(&frames, Some(preset)).with_context(|| {
                format!("photographing LED preset {preset} for the nodes' shape")
            })?;
            // Its own noise, so that the calibration's captures are those of a flat one.
            let mut own = CameraNoise::with_seed(room, REFERENCE_SEED);
            setup.reference = Some(image(&own.expose(&lit)));
            1
        }
    };
    let log = StageLog::new(bar.clone());
    let mut rig = SimRig::new(room, noise);
    let mut up = block_on(Procedure::new(&mut rig, settings, log.sink()).bring_up(&setup))
        .context("calibrating the room")?;
    up.captures += reference;
    for line in log.lines(&up, setup.corners.len()) {
        say(line);
    }
    Calibrated::new(room, setup, settings, up)
}

/// The procedure's events with when they came, shown on a progress bar as they come.
#[derive(Debug, Clone)]
struct StageLog {
    bar: indicatif::ProgressBar,
    events: Arc<Mutex<Vec<(Instant, Event)>>>,
}

impl StageLog {
    fn new(bar: indicatif::ProgressBar) -> Self {
        Self {
            bar,
            events: Arc::default(),
        }
    }

    /// The procedure's progress callback.
    fn sink(&self) -> impl FnMut(Event) + Send + 'static {
        let log = self.clone();
        move |e| {
            match &e {
                Event::Stage { stage, captures } => {
                    log.bar.reset();
                    log.bar.set_length(*captures as u64);
                    log.bar.set_message(stage_name(*stage));
                }
                Event::Captured { .. } => log.bar.inc(1),
                _ => {}
            }
            log.events
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .push((Instant::now(), e));
        }
    }

    /// One line per stage: captures, seconds, and what it found.
    fn lines(&self, up: &BringUp, charts: usize) -> Vec<String> {
        let events = self.events.lock().unwrap_or_else(PoisonError::into_inner);
        let mut lines = Vec::new();
        for (stage, captures, seconds) in stages(&events) {
            let detail = match stage {
                Stage::StructuredLight => structured_light_detail(&events),
                Stage::SecondPass => second_pass_detail(&events),
                Stage::Responses => responses_detail(&events),
                Stage::Attenuation => attenuation_detail(up),
                _ => String::new(),
            };
            lines.push(format!(
                "{}: {captures} captures, {seconds:.1} s{detail}",
                stage_name(stage)
            ));
        }
        for (projector, chart) in events.iter().filter_map(|(_, e)| match e {
            Event::WholeFrame { projector, chart } => Some((projector, chart)),
            _ => None,
        }) {
            lines.push(match chart {
                Some(c) => format!("{projector}: one node over its frame (chart {c})"),
                None => format!(
                    "{projector}: lights no chart; one node over its frame, started from the fallback"
                ),
            });
        }
        let shaped: Vec<String> = events
            .iter()
            .filter_map(|(_, e)| match e {
                Event::Shaped {
                    projector,
                    nodes,
                    spread,
                } => Some(format!(
                    "{projector} {nodes} ({:.2}–{:.2})",
                    spread.0, spread.1
                )),
                _ => None,
            })
            .collect();
        if !shaped.is_empty() {
            lines.push(format!(
                "nodes shaped to the reference photograph (5th–95th percentile of the shape): {}",
                shaped.join(", ")
            ));
        }
        let charted = up.placed.iter().filter(|p| p.layout == Layout::Charted);
        lines.push(format!(
            "nodes: {} ({} in projectors split by chart) over {} charts",
            up.columns.ids.len(),
            charted.map(|p| p.nodes.len()).sum::<usize>(),
            charts
        ));
        lines
    }
}

/// A stage as the bench and the demo print it.
pub(crate) fn stage_name(stage: Stage) -> &'static str {
    match stage {
        Stage::Dark => "dark",
        Stage::Footprints => "footprints",
        Stage::StructuredLight => "structured light",
        Stage::SecondPass => "second pass",
        Stage::Responses => "responses",
        Stage::Attenuation => "attenuation",
        Stage::Hot => "hot calibration",
    }
}

/// Each stage in the order first begun, with its captures and the seconds from its first
/// begin to the next stage's (to the last event for the last one).
fn stages(events: &[(Instant, Event)]) -> Vec<(Stage, usize, f64)> {
    let mut out: Vec<(Stage, usize, f64)> = Vec::new();
    let mut current: Option<(Stage, Instant)> = None;
    let end = events.last().map(|(at, _)| *at);
    for (at, e) in events {
        match e {
            Event::Stage { stage, .. } => {
                if let Some((s, since)) = current
                    && let Some(row) = out.iter_mut().find(|r| r.0 == s)
                {
                    row.2 += at.duration_since(since).as_secs_f64();
                }
                if !out.iter().any(|r| r.0 == *stage) {
                    out.push((*stage, 0, 0.0));
                }
                current = Some((*stage, *at));
            }
            Event::Captured { stage } => {
                if let Some(row) = out.iter_mut().find(|r| r.0 == *stage) {
                    row.1 += 1;
                }
            }
            _ => {}
        }
    }
    if let (Some((s, since)), Some(end)) = (current, end)
        && let Some(row) = out.iter_mut().find(|r| r.0 == s)
    {
        row.2 += end.duration_since(since).as_secs_f64();
    }
    out
}

fn structured_light_detail(events: &[(Instant, Event)]) -> String {
    let groups: Vec<String> = events
        .iter()
        .filter_map(|(_, e)| match e {
            Event::Grouped { groups } => Some(groups),
            _ => None,
        })
        .flatten()
        .map(|g| g.join(" + "))
        .collect();
    let decoded: Vec<String> = events
        .iter()
        .filter_map(|(_, e)| match e {
            Event::Decoded { projector, share } => {
                Some(format!("{projector} {:.1}%", 100.0 * share))
            }
            _ => None,
        })
        .collect();
    format!(
        "; coded {}; camera pixels decoded: {}",
        groups.join(", "),
        decoded.join(", ")
    )
}

fn second_pass_detail(events: &[(Instant, Event)]) -> String {
    let passes: Vec<String> = events
        .iter()
        .filter_map(|(_, e)| match e {
            Event::SecondPass { projector, pass } => Some(format!(
                "{projector}: {:.1}% of its frame shown at exposure ×{:.1}, {} pixels added",
                100.0 * pass.shown,
                pass.exposure,
                pass.taken
            )),
            _ => None,
        })
        .collect();
    format!("; {}", passes.join("; "))
}

fn responses_detail(events: &[(Instant, Event)]) -> String {
    let gammas: Vec<String> = events
        .iter()
        .filter_map(|(_, e)| match e {
            Event::Response { projector, gamma } => Some(format!(
                "{projector} γ {:.2}/{:.2}/{:.2}",
                gamma[0], gamma[1], gamma[2]
            )),
            Event::RampApart { reason } => Some(format!("shown apart: {reason}")),
            _ => None,
        })
        .collect();
    format!(
        " (the ramps' ends are the dark and white captures); {}",
        gammas.join(", ")
    )
}

fn attenuation_detail(up: &BringUp) -> String {
    let usable = &up.columns.attenuation.usable;
    format!(
        " (Hadamard, black from the dark capture) for {} nodes; {} of {} patches usable",
        up.columns.ids.len(),
        usable.iter().filter(|&&u| u).count(),
        usable.len()
    )
}

/// Captures the LED preset `preset` (projectors dark) and builds the model for it over the
/// patches measured in every capture ([`Target`]), with its conventional start; the target
/// patches, if calibration measured any, are left out (weight 0, [`Model::for_weight`]).
pub fn measure_target(
    room: &Room,
    cal: &Calibrated,
    preset: usize,
    noise: &mut CameraNoise,
) -> Result<Model> {
    Model::for_weight(cal, &measure_lit(room, cal, preset, noise)?, 0.0)
}

/// The LED preset `preset` (projectors dark), captured once through `noise` and sampled on
/// every room patch.
pub fn measure_lit(
    room: &Room,
    cal: &Calibrated,
    preset: usize,
    noise: &mut CameraNoise,
) -> Result<Vec<PatchSample>> {
    Ok(photograph_lit(room, cal, preset, noise)?.0)
}

/// [`measure_lit`], with the photograph its samples were read from.
pub fn photograph_lit(
    room: &Room,
    cal: &Calibrated,
    preset: usize,
    noise: &mut CameraNoise,
) -> Result<(Vec<PatchSample>, roomlight_sim::Capture)> {
    let frames = vec![Frame::Black; room.projectors().len()];
    let photo = noise.expose(&room.render(&frames, Some(preset))?);
    Ok((cal.sample_room(&photo)?, photo))
}

impl Model {
    /// The model for the LED target measured as `lit` ([`measure_lit`]), the target patches
    /// kept dark with weight `weight` ([`Target::with_dark`]; 0: left out, the model over the
    /// charts alone).
    pub fn for_weight(cal: &Calibrated, lit: &[PatchSample], weight: f64) -> Result<Self> {
        Self::for_weights(cal, lit, weight, cal.wall_weight)
    }

    /// [`Model::for_weight`] with the wall patches weighed `wall_weight` ([`Target::with_walls`];
    /// 0 leaves them out), the walls no node reaches left out.
    pub fn for_weights(
        cal: &Calibrated,
        lit: &[PatchSample],
        weight: f64,
        wall_weight: f64,
    ) -> Result<Self> {
        let att = &cal.attenuation;
        let walls = cal.wall_patch_range();
        let target = Target::new(&att.black, &att.usable, lit)?
            .with_dark(cal.target_patch_range(), weight)?
            .with_walls(walls.clone(), wall_weight)?
            .without_unreached(walls, &cal.columns);
        model_of(cal, target)
    }
}

fn model_of(cal: &Calibrated, target: Target) -> Result<Model> {
    let problem = target.problem(target.columns(&cal.columns)?)?;
    let charts = target.chart_patches(cal.corners.len(), PATCHES_PER_CHART);
    // A node without a chart gets an empty one, so the conventional start falls back (its
    // lights stay on).
    let conventional = problem
        .columns()
        .iter()
        .zip(&cal.node_charts)
        .map(|(c, chart)| {
            conventional_value(
                c,
                chart.map_or(&[][..], |m| &charts[m]),
                problem.target(),
                problem.black(),
                LinearRgb::splat(0.5),
            )
        })
        .collect::<Result<_, _>>()?;
    Ok(Model {
        problem,
        patches: target.patches.clone(),
        target,
        conventional,
    })
}
