//! The calibration procedure (DESIGN §4), written once against a [`Rig`]: black offset,
//! footprints, structured light with projectors whose footprints do not overlap coded at the
//! same time, the second pass where the first leaves reached pixels unknown, response ramps,
//! nodes (feathered across overlaps, the target kept dark, beside projectors already lit),
//! attenuation (one at a time or Hadamard) and hot calibration of a projector joining a lit
//! room. Every step is a method a caller may run on its own; [`Procedure::bring_up`] and
//! [`Procedure::join`] chain them for the two situations the system meets; [`Target`] turns
//! the target lighting's capture into the model's patches and problem. It owns the order
//! of captures and what is shown for each; it must not know where frames are shown or photos
//! come from (processes, networks, the simulator), nor what the caller does with the results.

use crate::CalibError;
use crate::attenuation::{Attenuation, Scheme, differential, plan, solve};
use crate::charts::{
    ChartCorners, PatchSample, PatchStatus, SampleConfig, sample_charts, sample_region,
};
use crate::graycode::{
    Coding, Correspondence, DecodeConfig, Manifest, Primary, SecondPass, SecondPassPlan, Unmixing,
    group_disjoint,
};
use crate::image_io::LinearImage;
use crate::nodes::{NodeConfig, charts_lit, segment_beside, whole_frame};
use crate::response::{Response, fit_response, footprint_ramp, ramp_codes};
use crate::rig::{Assignment, Frame, Projector, ProjectorKind, ProjectorRole, Rig, RigError};
use roomlight_core::LinearRgb;
use std::borrow::Borrow;

pub mod shape;
mod steps;
mod target;
mod target_patches;
mod walls;

pub use steps::Procedure;
pub use target::Target;
pub use target_patches::{TARGET_PATCH_GRID, target_patches};
pub use walls::{WallTiling, wall_exclusion, wall_patches};

/// How the procedure measures; [`Settings::default`] is what the benches measured best.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Decoder for standard projectors (XOR-04 coded).
    pub decode: DecodeConfig,
    /// Decoder for large apertures (plain Gray code, blurred by their defocus).
    pub decode_large: DecodeConfig,
    /// A camera pixel is in a standard projector's footprint when its white raises it by this
    /// share of its brightest pixel: inter-reflected light stays below it in the lab.
    pub footprint_share: f32,
    /// The same for a large aperture: its blur's tail carries plain Gray code's coarse stripes
    /// (which inter-reflection does not average away) well below a tenth of its peak. At 0.1 the
    /// lab grouped floor-right with the large aperture, and 0.32% of floor-right's decoded
    /// pixels came out off by more than 2 (none coded alone).
    pub footprint_share_large: f32,
    /// Levels of the response ramp, its ends (the dark and white captures) included: a power
    /// law per channel has one parameter, so two levels between the ends fit it and check the
    /// fit.
    pub ramp_levels: usize,
    /// Every projector brought up together shows each ramp level at once, one capture a
    /// level, the shares told apart by their whites ([`crate::shared_ramp`]); otherwise (or
    /// when they cannot be told apart) each shows its levels alone.
    pub ramp_together: bool,
    /// How the attenuation of a room brought up is multiplexed.
    pub scheme: Scheme,
    /// How projectors are split into nodes and feathered.
    pub nodes: NodeConfig,
    /// Whether the camera resolves XOR-04's 4-pixel stripes on standard projectors. A camera
    /// that sees several projector pixels in one of its own (an evaluation camera close to
    /// the projector) averages them away; it needs plain Gray code, as a defocused
    /// projector does ([`Settings::coding`]).
    pub fine_stripes: bool,
    /// Capture each bit pattern of an XOR-coded projector once, without its inverse: half
    /// the structured light's captures ([`crate::graycode::Captures::single_shot`]). On the
    /// photographic tests it leaves 0.5% more lit pixels unknown and none wrong. Plain Gray
    /// code always shows both.
    pub single_shot: bool,
    /// Code each projector over cells of projector pixels as large as the camera needs to
    /// resolve its finest stripes ([`code_cell`]): a bit fewer per axis at each doubling.
    pub cells: bool,
    /// Code up to three groups of projectors at the same time whatever their footprints,
    /// each in its own primary, told apart by the camera's colour
    /// ([`crate::graycode::Unmixing`]): a set of three takes its slots once (every member's
    /// pairs), plus a capture of each group's primary white. On by default: on the lab it
    /// brings the bring-up from 154 captures to 112 (to first converged light 159 → 118, issue
    /// 21's bar 120); one primary carries a third of white's light, so the floor projectors
    /// decode 1.6–3.5% fewer of their pixels (left unknown) and the partition of unity in
    /// overlaps is 96.51% within 1e-3 against 97.33% in white, but the demo's charts end
    /// 0.03–0.05 ΔE00 better (docs/results.md, 2026-12-07). Off for projectors that do not
    /// show their primaries at once (a single-chip DLP's colour wheel photographed faster than
    /// it turns), and in a lit room ([`Self::lit_room`]).
    pub primaries: bool,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            decode: DecodeConfig::default(),
            decode_large: DecodeConfig::strict(),
            footprint_share: 0.1,
            footprint_share_large: 0.01,
            ramp_levels: 4,
            ramp_together: true,
            scheme: Scheme::Hadamard,
            nodes: NodeConfig::default(),
            fine_stripes: true,
            single_shot: true,
            cells: true,
            primaries: true,
        }
    }
}

impl Settings {
    /// The coding a projector gets: XOR-04 where the projector's optics and the camera
    /// resolve its fine stripes, plain Gray code otherwise ([`coding`]).
    pub fn coding(&self, p: &Projector) -> Coding {
        if self.fine_stripes {
            coding(p)
        } else {
            Coding::Gray
        }
    }

    /// The settings for projectors calibrated while others light the room: every bit pattern
    /// with its inverse. Shown once, a difference is 2·pattern − white, so the white must not
    /// clip and the others' light must stay as the dark and white captures saw it; the
    /// others' light makes the first likelier and a pair needs neither. Where white clips a
    /// single shot now reads a pixel from its own patterns (`Captures::single_shot`), which
    /// took the wrong codes out (the small room's joiner: 0.27% off by more than 2 → none),
    /// and the lab's hot join shown once takes 28 captures with the same partition of unity
    /// after it as pairs (48); but over the wire the rendered room's joiner shown once still
    /// reached 1% of the optimum 17 captures after its calibration against 3 with pairs (the
    /// processes test, 2026-11-28): pairs there as before. Not for want of the camera's
    /// ceiling (the rendered room now reports it, and the figures did not move): that
    /// calibration is deterministic, and shown once the joiner's second node's column differs
    /// from the pairs' by 2.7% of its light (up to 68% on one dim patch), its model optimum
    /// lies 1.8% higher, and the measured objective stays about 1% above it for 17 captures
    /// (53 in one run). Which of the two columns is nearer the truth is not yet known.
    /// Coded in white too: a batch joining a lit room, whose light adds its shot noise to a
    /// primary's third of white, has not been measured in primaries (a single joiner is one
    /// group, coded in white either way).
    pub fn lit_room(self) -> Self {
        Self {
            single_shot: false,
            primaries: false,
            ..self
        }
    }

    /// Whether projector `p`'s bit patterns are shown without their inverses
    /// ([`Settings::single_shot`]; XOR coding only).
    pub fn shows_once(&self, p: &Projector) -> bool {
        self.single_shot && self.coding(p) == Coding::Xor04
    }

    /// The decoder for a projector: strict for a large aperture, whose blur makes a stripe
    /// edge undecided rather than off by the blur.
    pub fn decoder(&self, p: &Projector) -> DecodeConfig {
        match p.kind {
            ProjectorKind::LargeAperture => self.decode_large,
            ProjectorKind::Standard => self.decode,
        }
    }
}

/// The room as configured by hand: where the charts are in the camera image, how they are
/// sampled, and which camera pixels the projection-mapping target covers.
#[derive(Debug, Clone, PartialEq)]
pub struct Setup {
    pub corners: Vec<ChartCorners>,
    pub sample: SampleConfig,
    pub target_mask: Vec<bool>,
    /// Camera regions on the target (pixel lists, [`target_patches`]) measured like chart
    /// patches, after them: room patches `24 · charts ..`, so that the light the nodes throw on
    /// the target can enter the objective ([`Target::with_dark`]). Empty: none (as before).
    pub target_patches: Vec<Vec<u32>>,
    /// Camera tiles of the room beyond the charts and the target ([`wall_patches`]), measured
    /// like chart patches after the target patches, so that the objective can ask for the
    /// target lighting everywhere the camera sees a lit surface ([`Target::with_walls`]).
    /// Empty: none (the model over the charts, as before).
    pub wall_patches: Vec<Vec<u32>>,
    /// The room under its own lighting with every projector dark, at the calibration's
    /// exposure: the luminaires' nodes are shaped to its falloff ([`shape`]). `None`: nodes
    /// flat over their regions, as before.
    pub reference: Option<LinearImage>,
}

impl Setup {
    /// Every room patch of a capture: the charts' patches, chart by chart, then the target
    /// patches, then the wall patches.
    pub fn sample_room(&self, image: &LinearImage) -> Result<Vec<PatchSample>, CalibError> {
        let mut all = sample_charts(image, &self.corners, &self.sample)?;
        all.extend(
            self.target_patches
                .iter()
                .chain(&self.wall_patches)
                .map(|r| sample_region(image, r, &self.sample)),
        );
        Ok(all)
    }

    /// The room patches that are wall patches.
    pub fn wall_patch_range(&self) -> std::ops::Range<usize> {
        let first = self.target_patch_range().end;
        first..first + self.wall_patches.len()
    }

    /// Every camera pixel a room patch's sampling may read beside the charts' (the target and
    /// wall patches' pixels).
    pub fn region_pixels(&self) -> impl Iterator<Item = u32> + '_ {
        self.target_patches
            .iter()
            .chain(&self.wall_patches)
            .flatten()
            .copied()
    }

    /// The room patches that are target patches.
    pub fn target_patch_range(&self) -> std::ops::Range<usize> {
        let first = self.corners.len() * crate::charts::COLUMNS * crate::charts::ROWS;
        first..first + self.target_patches.len()
    }
}

/// The steps, for progress.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    Dark,
    Footprints,
    StructuredLight,
    SecondPass,
    Responses,
    Attenuation,
    Hot,
}

/// What the procedure reports while it runs (nothing is printed).
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A step begins and plans about this many captures.
    Stage { stage: Stage, captures: usize },
    /// One capture taken.
    Captured { stage: Stage },
    /// The projectors coded at the same time, group by group.
    Grouped { groups: Vec<Vec<String>> },
    /// Groups coded at the same time in their primaries, set by set (only when some set has
    /// more than one group).
    Primaries {
        sets: Vec<Vec<(Primary, Vec<String>)>>,
    },
    /// A projector's structured light decoded (share of camera pixels).
    Decoded { projector: String, share: f64 },
    /// A second pass over what the first left unknown.
    SecondPass { projector: String, pass: SecondPass },
    /// A projector's response fitted.
    Response { projector: String, gamma: [f64; 3] },
    /// The ramp shown by every projector at once was refused (why): each shows its levels
    /// alone instead ([`Settings::ramp_together`]).
    RampApart { reason: String },
    /// A projector made one node over its frame (a large aperture, or one that lights no
    /// chart), with the chart it lights most.
    WholeFrame {
        projector: String,
        chart: Option<usize>,
    },
    /// A projector's nodes shaped to the reference ([`shape`]): the 5th and 95th percentiles
    /// of the shape over its driven pixels.
    Shaped {
        projector: String,
        nodes: usize,
        spread: (f32, f32),
    },
}

/// Why a step failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProcedureError {
    #[error(transparent)]
    Rig(#[from] RigError),
    /// A measurement of one projector was refused.
    #[error("{projector}: {source}")]
    Projector {
        projector: String,
        #[source]
        source: CalibError,
    },
    #[error(transparent)]
    Calib(#[from] CalibError),
}

/// A projector's structured light decoded, and the second pass if one was taken.
#[derive(Debug, Clone, PartialEq)]
pub struct Decoded {
    pub projector: Projector,
    /// The pattern set it was coded with (its coding and code cell).
    pub manifest: Manifest,
    pub corr: Correspondence,
    /// The decoder its first pass was decoded with, before scaling to its captures' exposure
    /// ([`Settings::decoder`], in one primary's noise where its set was coded in primaries):
    /// what its reached but unknown pixels are judged by ([`place_calibrated`]), as its
    /// group's inverses after a single shot are.
    pub decoder: DecodeConfig,
    pub second: Option<SecondPass>,
}

/// A projector decoded and its response fitted.
#[derive(Debug, Clone, PartialEq)]
pub struct Measured {
    pub projector: Projector,
    /// The pattern set it was coded with (its coding and code cell).
    pub manifest: Manifest,
    pub corr: Correspondence,
    /// As [`Decoded::decoder`].
    pub decoder: DecodeConfig,
    pub response: Response,
    pub second: Option<SecondPass>,
}

/// How a projector was split into nodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// One node per chart it lights, feathered against the others.
    Charted,
    /// One node over its whole frame but the target (a large aperture, or a standard
    /// projector that lights no chart).
    WholeFrame,
}

/// One node: its id, the chart whose region it is (for the conventional start), and the
/// weight of every projector pixel (row-major, in `[0, 1]`).
#[derive(Debug, Clone, PartialEq)]
pub struct PlacedNode {
    pub id: u32,
    pub chart: Option<usize>,
    pub weights: Vec<f32>,
}

/// A projector's nodes.
#[derive(Debug, Clone, PartialEq)]
pub struct Placed {
    pub projector: Projector,
    pub layout: Layout,
    pub nodes: Vec<PlacedNode>,
    /// Per camera pixel, the share of the light there its nodes give
    /// ([`crate::nodes::Segmentation::claims`]); `None` for a whole-frame node, which does not
    /// blend with others.
    pub claim: Option<Vec<f32>>,
    /// Projector pixels kept black for the target (charted projectors; empty otherwise).
    pub excluded: Vec<bool>,
    pub response: Response,
    /// How its nodes were shaped to the room's reference ([`shape`]); `None`: flat.
    pub shape: Option<shape::Shape>,
}

impl Placed {
    /// How the projector draws its nodes: sparse weights, capped at 1.
    pub fn assignment(&self) -> Assignment {
        Assignment {
            width: self.projector.width,
            height: self.projector.height,
            response: self.response.clone(),
            nodes: self
                .nodes
                .iter()
                .map(|n| {
                    let sparse = n
                        .weights
                        .iter()
                        .enumerate()
                        .filter(|(_, w)| **w > 0.0)
                        .map(|(i, w)| (i as u32, w.min(1.0)))
                        .collect();
                    (n.id, sparse)
                })
                .collect(),
        }
    }

    /// The node ids, in order.
    pub fn ids(&self) -> Vec<u32> {
        self.nodes.iter().map(|n| n.id).collect()
    }
}

/// Attenuation of every node, column `j` being node `ids[j]`'s.
#[derive(Debug, Clone, PartialEq)]
pub struct Columns {
    pub ids: Vec<u32>,
    pub attenuation: Attenuation,
}

/// A hot projector's nodes measured differentially while the rest of the room keeps its light
/// (DESIGN §4.7): each node's `p` per room patch (white − black, not clipped) and its standard
/// deviation, and which patches every capture could measure.
#[derive(Debug, Clone, PartialEq)]
pub struct Hot {
    pub columns: Vec<(u32, Vec<LinearRgb>)>,
    pub sigma: Vec<Vec<LinearRgb>>,
    pub measurable: Vec<bool>,
    /// The room with this projector's nodes black.
    pub black: Vec<PatchSample>,
}

/// A room brought up from dark.
#[derive(Debug, Clone, PartialEq)]
pub struct BringUp {
    pub measured: Vec<Measured>,
    pub placed: Vec<Placed>,
    pub columns: Columns,
    /// Captures taken in all.
    pub captures: usize,
}

/// A projector calibrated while the others stay lit.
#[derive(Debug, Clone, PartialEq)]
pub struct Joined {
    pub measured: Measured,
    pub placed: Placed,
    pub hot: Hot,
    /// Captures taken in all.
    pub captures: usize,
}

/// The luminaires among `projectors` (texture projectors are kept dark, not calibrated).
pub fn luminaires(projectors: &[Projector]) -> Vec<Projector> {
    projectors
        .iter()
        .filter(|p| p.role == ProjectorRole::Luminaire)
        .cloned()
        .collect()
}

/// The share of a surface point's light the projectors already lit may leave to one joining
/// them before the joiner is needed there ([`needed`]): the partition of unity's tighter
/// tolerance. Below it, the joiner's weight is at most this however well it is decoded.
pub const LEFT_TO_JOINER: f32 = 1e-3;

/// A standard luminaire calibrated with others that leaves more of its reached pixels unknown
/// than this share of its decoded ones, judged on the noise it was decoded with
/// ([`Decoded::decoder`]), is placed beside the others as a joiner is ([`goes_beside`]). The
/// lab coded in primaries (`roomlight bench calib`, 2026-12-07): walls and floor-left leave
/// 0.00–0.08%, floor-right 1.04% (a grazing face the others light); 0.81% on white's higher
/// noise floor, which segmented it with the others (overlaps within 1e-3 93.58% against
/// 96.51% beside, charts 0.07–0.28 ΔE00 worse). Coded in white, 0.00–0.70% and 5.41%.
pub const BESIDE_UNKNOWN: f64 = 0.01;

/// The camera pixels where a projector joining a lit room is needed: those where the
/// projectors already lit, whose claims sum to `claimed`, leave more than [`LEFT_TO_JOINER`]
/// of the light (a share that is not finite counts as needing it).
pub fn needed(claimed: &[f32]) -> Vec<bool> {
    claimed
        .iter()
        .map(|c| c.is_nan() || *c < 1.0 - LEFT_TO_JOINER)
        .collect()
}

/// What `placed` projectors give each of a camera's `pixels` together: the sum of their claims
/// (a whole-frame node, which has none, gives nothing), what a projector joining them is placed
/// beside ([`needed`], [`place`]).
pub fn claimed_by(placed: &[Placed], pixels: usize) -> Vec<f32> {
    let mut claimed = vec![0.0f32; pixels];
    for p in placed {
        if let Some(c) = &p.claim {
            crate::nodes::add_claim(&mut claimed, c);
        }
    }
    claimed
}

/// The coding a projector's optics allow: a large aperture's defocus blurs XOR-04's fine
/// stripes away, so it gets plain Gray code (for a camera that resolves the stripes; see
/// [`Settings::coding`]).
pub fn coding(p: &Projector) -> Coding {
    match p.kind {
        ProjectorKind::LargeAperture => Coding::Gray,
        ProjectorKind::Standard => Coding::Xor04,
    }
}

/// Groups of projectors (indices into `whites`) whose footprints do not overlap
/// ([`group_disjoint`]), from each one's white capture minus `dark` ([`footprints`]).
pub fn coding_groups(
    projectors: &[Projector],
    dark: &LinearImage,
    whites: &[LinearImage],
    settings: &Settings,
) -> Vec<Vec<usize>> {
    group_disjoint(&footprints(projectors, dark, whites, settings))
}

/// The camera pixels each projector's white raises above `dark` by more than its footprint
/// share of its peak ([`Settings::footprint_share`], [`Settings::footprint_share_large`]).
pub fn footprints(
    projectors: &[Projector],
    dark: &LinearImage,
    whites: &[LinearImage],
    settings: &Settings,
) -> Vec<Vec<bool>> {
    let dark = dark.intensity();
    projectors
        .iter()
        .zip(whites)
        .map(|(p, white)| {
            let gain = gain(white, &dark);
            let peak = gain.iter().copied().fold(0.0f32, f32::max);
            let share = match p.kind {
                ProjectorKind::LargeAperture => settings.footprint_share_large,
                ProjectorKind::Standard => settings.footprint_share,
            };
            gain.iter().map(|g| *g > share * peak).collect()
        })
        .collect()
}

/// The camera pixels a projector lights directly, as its white shows them (`gain`, its rise
/// above dark; `footprint`, the pixels [`footprints`] gives it): those raised above
/// [`DIRECT_SHARE`] of the footprint's 99th percentile. What [`code_cell`] sizes the cells
/// by. The footprint's share of the peak (10%) counts the light the walls reflect onto one
/// another too: in the lab the wall projectors' footprints were 2.7–3.0 times the camera
/// pixels they light directly (333 114 against 119 908 for wall-left, the simulator's truth),
/// which made them look finer than the camera and gave them cells of 2, where a real
/// camera's lens blurs such stripes into grey (the photographic test: 51% in their cell or
/// beside it, against 99.91% over cells of 4). This count is 63–171% of the direct one there
/// (floor-right 44 185 against 70 688, wall-front 159 668 against 93 551; `roomlight bench
/// calib`, 2026-12-07), and 2.7 times it in the small room, whose white walls stand close to
/// its projectors: an estimate, not a measurement. 0 for an empty footprint.
pub fn direct_footprint(gain: &[f32], footprint: &[bool]) -> usize {
    let mut lit: Vec<f32> = gain
        .iter()
        .zip(footprint)
        .filter(|&(g, &f)| f && g.is_finite())
        .map(|(g, _)| *g)
        .collect();
    if lit.is_empty() {
        return 0;
    }
    let k = (lit.len() * 99 / 100).min(lit.len() - 1);
    let (_, top, _) = lit.select_nth_unstable_by(k, f32::total_cmp);
    let floor = DIRECT_SHARE * *top;
    gain.iter().filter(|&&g| g > floor).count()
}

/// The camera pixels [`code_cell`] sizes a projector's cells by: those it lights directly
/// ([`direct_footprint`]) for a standard projector; for a large aperture, its whole footprint
/// (down to 1% of its peak), which gives it cells of 2 in the lab. Its in-focus pixels must
/// be placed within ±1 projector pixel (issue 21 item 7's bar, 98%): over cells of 2 the
/// simulated lab places 99.98% of them so, over cells of 4, which its direct footprint would
/// give, 97.92% (`roomlight bench calib`, 2026-12-07). A real lens blurs stripes of 4 pixels
/// of it (1.2 camera pixels) as it does a wall projector's; its light-weighted centroids
/// (`crate::centroid`) are the measure that does not depend on them.
pub fn cell_footprint(p: &Projector, gain: &[f32], footprint: &[bool]) -> usize {
    match p.kind {
        ProjectorKind::LargeAperture => footprint.iter().filter(|&&lit| lit).count(),
        ProjectorKind::Standard => direct_footprint(gain, footprint),
    }
}

/// The share of a footprint's 99th percentile above which a camera pixel counts as lit
/// directly ([`direct_footprint`]). At 10% of the peak the lab's walls counted 333 000–377 000
/// camera pixels, at 20% of it 88 000–104 000, where they light 120 000–124 000 directly
/// (2026-12-07): the reflected light lies between, and so does this share. Direct light on
/// surfaces seen at a grazing angle falls below it too.
pub const DIRECT_SHARE: f32 = 0.2;

/// The code cell of a projector whose footprint covers `footprint` camera pixels
/// ([`Manifest::cell`]): the smallest power of two (up to [`LARGEST_CELL`]) whose finest
/// stripes, two cells wide, span at least [`STRIPE_CAMERA_PX`] camera pixels where a camera
/// pixel sees `s` = √(projector pixels / `footprint`) projector pixels a side (the footprint's
/// average): cell ≥ `STRIPE_CAMERA_PX` · s / 2. Narrower stripes a lens blurs into grey:
/// photographs of a projector finer than the camera (the photographic tests, 2.4 projector
/// pixels a camera pixel) decode 10% of their lit pixels within ±1 at full resolution and 51%
/// in their cell or beside it over cells of two, against 99.91% over cells of four. Each
/// doubling saves a bit per axis (2 captures shown once, 4 with inverses); a decode is then
/// right within [`Manifest::tolerance`], placed within its cell by its neighbours
/// (`graycode::cells`). No footprint (a projector the camera does not see, refused later): 1.
pub fn code_cell(p: &Projector, footprint: usize) -> u32 {
    let pixels = f64::from(p.width) * f64::from(p.height);
    if footprint == 0 {
        return 1;
    }
    let s = (pixels / footprint as f64).sqrt();
    let mut cell = 1;
    while f64::from(cell) < STRIPE_CAMERA_PX * s / 2.0 && cell < LARGEST_CELL {
        cell *= 2;
    }
    cell
}

/// The largest cell [`code_cell`] gives. XOR-04's base stripes are four cells wide, and the
/// single shot reads a pattern against half of white's reflected light, which holds less as
/// the stripes widen: the lab's procedure test at a 320×240 camera (some nine projector pixels
/// a camera pixel) had wall-front's group shown its inverses after all over cells of 8, and
/// two groups over cells of 16 (2026-11-29). A footprint foreshortened along one axis takes
/// its inverses already over cells of 4 (the apart room's right projector, `docs/calibration.md`).
pub const LARGEST_CELL: u32 = 4;

/// The narrowest stripe, in camera pixels, a code is given ([`code_cell`]): the photographic
/// tests decode 99.26% of lit pixels within ±1 with their finest stripes 2.5 camera pixels
/// wide (a 128-pixel projector across 160 camera pixels, 1-pixel blur).
pub const STRIPE_CAMERA_PX: f64 = 2.5;

/// How much a white raises each camera pixel above `dark` (intensities).
pub(super) fn gain(white: &LinearImage, dark: &[f32]) -> Vec<f32> {
    white
        .intensity()
        .iter()
        .zip(dark)
        .map(|(w, b)| w - b)
        .collect()
}

/// For each member of a group coded together, the camera pixels it decodes: those its white
/// raises most (`None` for a projector coded alone).
pub(super) fn owned_pixels(group: &[usize], gains: &[Vec<f32>]) -> Vec<Option<Vec<bool>>> {
    group
        .iter()
        .map(|&k| {
            (group.len() > 1).then(|| {
                (0..gains[k].len())
                    .map(|i| !group.iter().any(|&o| o != k && gains[o][i] > gains[k][i]))
                    .collect()
            })
        })
        .collect()
}

/// Whether [`place_calibrated`] places `m` beside the others ([`BESIDE_UNKNOWN`]).
pub fn goes_beside(m: &Measured) -> bool {
    m.projector.blends() && m.corr.reached_unknown_share(&m.decoder) > BESIDE_UNKNOWN
}

/// Places projectors calibrated together ([`place`]), beside projectors already lit
/// (`claimed`) if any: first those decoded in full, then, beside them too, those that
/// [`goes_beside`] picks, as joiners are placed. Structured light spent no inverses or second
/// pass where another blending projector was decoded ([`Procedure::structured_light`]);
/// segmented all together, such a projector's blend guessed at the face it left unknown where
/// the others already give all the light (the lab's bring-up: 98.44% of overlap points within
/// 0.05, against 99.70% beside). In that order, first then beside; ids from `first_node` on.
pub fn place_calibrated(
    setup: &Setup,
    measured: &[Measured],
    claimed: Option<&[f32]>,
    first_node: u32,
    settings: &Settings,
    progress: &mut dyn FnMut(Event),
) -> Result<Vec<Placed>, CalibError> {
    let (rest, first): (Vec<&Measured>, Vec<_>) = measured.iter().partition(|m| goes_beside(m));
    if first.is_empty() || rest.is_empty() {
        return place(
            setup,
            measured,
            claimed,
            first_node,
            &settings.nodes,
            progress,
        );
    }
    let mut placed = place(
        setup,
        &first,
        claimed,
        first_node,
        &settings.nodes,
        progress,
    )?;
    let pixels = rest[0].corr.map.len();
    let mut beside = claimed.map_or_else(|| vec![0.0; pixels], <[f32]>::to_vec);
    for c in placed.iter().filter_map(|p| p.claim.as_ref()) {
        crate::nodes::add_claim(&mut beside, c);
    }
    let next = first_node + placed.iter().map(|p| p.nodes.len() as u32).sum::<u32>();
    placed.extend(place(
        setup,
        &rest,
        Some(&beside),
        next,
        &settings.nodes,
        progress,
    )?);
    Ok(placed)
}

/// Splits measured projectors into nodes, ids from `first_node` on in the order given:
/// standard ones that light a chart together, feathered against each other and beside
/// projectors already lit (`claimed`: the sum of their claims,
/// [`crate::nodes::add_claim`]); a large aperture, or a projector that lights no chart, one
/// node over its frame but the target ([`whole_frame`]).
pub fn place<M: Borrow<Measured>>(
    setup: &Setup,
    measured: &[M],
    claimed: Option<&[f32]>,
    first_node: u32,
    config: &NodeConfig,
    progress: &mut dyn FnMut(Event),
) -> Result<Vec<Placed>, CalibError> {
    let measured: Vec<&Measured> = measured.iter().map(Borrow::borrow).collect();
    let charted: Vec<bool> = measured
        .iter()
        .map(|m| {
            m.projector.kind == ProjectorKind::Standard
                && charts_lit(&m.corr, &setup.corners, config).is_ok_and(|c| !c.is_empty())
        })
        .collect();
    let together: Vec<Correspondence> = measured
        .iter()
        .zip(&charted)
        .filter(|(_, c)| **c)
        .map(|(m, _)| m.corr.clone())
        .collect();
    let mut seg = segment_beside(
        &together,
        &setup.corners,
        Some(&setup.target_mask),
        config,
        claimed,
    )?;
    let (mut next, mut slot) = (first_node, 0usize);
    let mut placed = Vec::with_capacity(measured.len());
    for (m, charted) in measured.iter().zip(charted) {
        let (layout, nodes, claim, excluded) = if charted {
            let nodes: Vec<(Option<usize>, Vec<f32>)> = seg
                .nodes
                .iter_mut()
                .filter(|n| n.projector == slot)
                .map(|n| (Some(n.chart), std::mem::take(&mut n.weights)))
                .collect();
            let claim = std::mem::take(&mut seg.claims[slot]);
            let excluded = std::mem::take(&mut seg.excluded[slot]);
            slot += 1;
            (Layout::Charted, nodes, Some(claim), excluded)
        } else {
            let (weights, chart) = whole_frame(&m.corr, &setup.corners, &setup.target_mask);
            progress(Event::WholeFrame {
                projector: m.projector.id.clone(),
                chart,
            });
            (Layout::WholeFrame, vec![(chart, weights)], None, Vec::new())
        };
        let nodes = nodes
            .into_iter()
            .map(|(chart, weights)| {
                next += 1;
                PlacedNode {
                    id: next - 1,
                    chart,
                    weights,
                }
            })
            .collect();
        placed.push(Placed {
            projector: m.projector.clone(),
            layout,
            nodes,
            claim,
            excluded,
            response: m.response.clone(),
            shape: None,
        });
    }
    Ok(placed)
}
