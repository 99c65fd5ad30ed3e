//! Projection mapping under the three lightings (DESIGN §5): the texture projector warps
//! generated textures onto the target through its decoded correspondences, compensating the
//! target's albedo and the ambient light that reaches it; a 4×4 checker on a 200 mm board in
//! place of the bust gives the ANSI contrast. Each is captured in a dark room, under the LED
//! preset, and under the projectors' lighting, by an evaluation camera near the texture projector
//! (the room camera sees the bust at about 25 pixels across).

use crate::pipeline::{Calibrated, FrameBuilder, SimRig};
use anyhow::{Context, Result, bail};
use roomlight_calib::graycode::Correspondence;
use roomlight_calib::procedure::{Procedure, Settings};
use roomlight_calib::rig::block_on;
use roomlight_core::LinearRgb;
use roomlight_core::metrics::{GrayImage, Rect, ansi_contrast, luminance, rms_contrast};
use roomlight_sim::scene::{ObjectSpec, ProjectorRole, Scene, ShapeKind};
use roomlight_sim::{CameraNoise, Capture, Frame, NodeRegion, ProjectorImage, Room};
use std::path::Path;

/// The three lightings.
pub const CONDITIONS: [&str; 3] = ["dark", "led", "projector"];

/// The generated textures.
pub const TEXTURES: [&str; 4] = ["crack", "camouflage", "radial", "tiles"];

/// What projection mapping measured.
#[derive(Debug, Clone, serde::Serialize)]
pub struct PmResult {
    /// ANSI contrast of the checker on the board, per condition (dark, led, projector), under
    /// the first lighting.
    pub ansi_contrast: [f64; 3],
    /// The same for every lighting (preset name; the dark room's value is shared).
    pub ansi_by_preset: Vec<(String, [f64; 3])>,
    /// Linear 16-bit PNGs written and their scales (linear value per code).
    pub linear: Vec<(String, f64)>,
    /// RMS contrast of each texture on the bust, per condition.
    pub rms_contrast: Vec<(String, [f64; 3])>,
    /// Images written, with captions.
    pub images: Vec<(String, String)>,
    /// Share of the target's camera pixels the texture projector's decode reached.
    pub decoded_share: f64,
    /// The board's ANSI contrast under projector lighting with each of the extra lightings
    /// `run` was given (the dark-target trade-off curve's optima), in their order.
    pub tradeoff_ansi: Vec<f64>,
}

/// The lab seen by an evaluation camera near the texture projector; with `board`, the bust
/// replaced by a 200 × 200 mm white board facing the texture projector.
pub fn evaluation_scene(base: &Scene, board: bool, room_camera: bool) -> Result<Scene> {
    let mut scene = base.clone();
    if board {
        let (bust, rest): (Vec<ObjectSpec>, Vec<ObjectSpec>) =
            scene.objects.into_iter().partition(|o| o.target);
        let Some(first) = bust.first() else {
            bail!("scene {} has no target to replace with a board", base.name);
        };
        // Standing on whatever the bust stood on: its lowest point.
        let bottom = bust
            .iter()
            .map(|o| match o.shape {
                ShapeKind::Sphere => o.center_mm[2] - o.radius_mm.unwrap_or(0.0),
                ShapeKind::Cylinder => o.center_mm[2] - 0.5 * o.height_mm.unwrap_or(0.0),
                _ => o.center_mm[2] - 0.5 * o.size_mm.map_or(0.0, |s| s[2]),
            })
            .fold(f64::INFINITY, f64::min);
        scene.objects = rest;
        scene.objects.push(ObjectSpec {
            name: "contrast-board".into(),
            shape: ShapeKind::Box,
            center_mm: [first.center_mm[0], first.center_mm[1], bottom + 5.0],
            size_mm: Some([200.0, 200.0, 10.0]),
            radius_mm: None,
            height_mm: None,
            yaw_deg: 0.0,
            albedo: [0.8, 0.8, 0.8],
            target: true,
        });
    }
    if !room_camera {
        let texture = scene
            .projectors
            .iter()
            .find(|p| p.role == ProjectorRole::Texture)
            .with_context(|| format!("scene {} has no texture projector", base.name))?;
        let target = texture.look_at_mm;
        let from = texture.position_mm;
        // Beside the texture projector, a little to the left, looking at the same point.
        scene.camera.position_mm = [from[0] - 150.0, from[1] + 50.0, from[2] - 50.0];
        scene.camera.look_at_mm = target;
        scene.camera.up = [0.0, 0.0, 1.0];
        scene.camera.fov_deg = 40.0;
        scene.camera.resolution = [320, 240];
        // A photometer rather than a camera: no clipping, so contrast is not capped by it.
        scene.camera.saturation = 1e6;
    }
    Ok(scene)
}

/// Decodes the texture projector's structured light through the evaluation camera, with the
/// one calibration procedure on the evaluation view as a rig: its black and white, then its
/// patterns. Plain Gray code: the evaluation camera sees several projector pixels in one of
/// its own, which averages XOR-04's 4-pixel stripes away.
fn decode_texture(room: &Room, k: usize, noise: &mut CameraNoise) -> Result<Correspondence> {
    let texture = [crate::pipeline::projector(room, k)];
    let settings = Settings {
        fine_stripes: false,
        ..Settings::default()
    };
    let mut rig = SimRig::new(room, noise);
    let mut procedure = Procedure::new(&mut rig, settings, |_| {});
    let decoded = block_on(async {
        let dark = procedure.dark(&texture).await?;
        let whites = procedure.whites(&texture).await?;
        procedure.code(&texture, &dark, &whites, None).await
    })?;
    decoded
        .into_iter()
        .next()
        .map(|d| d.corr)
        .context("the texture projector was not decoded")
}

/// A texture in `[0, 1]` at normalised target coordinates `(s, t)` in `[0, 1]²`.
fn texture(name: &str, s: f64, t: f64) -> f64 {
    use std::f64::consts::TAU;
    match name {
        // Dark lines where two Voronoi cells meet.
        "crack" => {
            let seeds = (0..12).map(|i| {
                let a = f64::from(i);
                (
                    (0.5 + 0.5 * (a * 12.9898).sin()).fract().abs(),
                    (0.5 + 0.5 * (a * 78.233).cos()).fract().abs(),
                )
            });
            let mut d: Vec<f64> = seeds.map(|(x, y)| (x - s).hypot(y - t)).collect();
            d.sort_by(f64::total_cmp);
            if d.len() > 1 && d[1] - d[0] < 0.02 {
                0.05
            } else {
                0.9
            }
        }
        // Three levels from a sum of waves.
        "camouflage" => {
            let v = (TAU * (2.0 * s + 0.5 * t)).sin()
                + (TAU * (1.3 * t - 0.7 * s) + 1.0).sin()
                + 0.7 * (TAU * 3.1 * (s + t)).sin();
            if v > 0.6 {
                0.9
            } else if v > -0.6 {
                0.5
            } else {
                0.1
            }
        }
        "radial" => {
            let a = (t - 0.5).atan2(s - 0.5);
            0.5 + 0.45 * (12.0 * a).cos()
        }
        // Light tiles with dark grout.
        _ => {
            let (u, v) = ((6.0 * s).fract(), (6.0 * t).fract());
            if u < 0.1 || v < 0.1 { 0.05 } else { 0.85 }
        }
    }
}

/// The target's bounding box in the camera image.
fn bounds(mask: &[bool], width: u32) -> Option<(u32, u32, u32, u32)> {
    let mut b: Option<(u32, u32, u32, u32)> = None;
    for (i, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
        let (x, y) = (i as u32 % width, i as u32 / width);
        b = Some(b.map_or((x, y, x, y), |(a, c, d, e)| {
            (a.min(x), c.min(y), d.max(x), e.max(y))
        }));
    }
    b
}

/// The largest centred axis-aligned rectangle inside the mask, shrinking the bounding box.
fn inner_rect(mask: &[bool], width: u32) -> Option<Rect> {
    let (x0, y0, x1, y1) = bounds(mask, width)?;
    let (mut a, mut b, mut c, mut d) = (x0, y0, x1, y1);
    while a < c && b < d {
        let full = (b..=d).all(|y| (a..=c).all(|x| mask[(y * width + x) as usize]));
        if full {
            return Some(Rect {
                x: f64::from(a),
                y: f64::from(b),
                width: f64::from(c - a + 1),
                height: f64::from(d - b + 1),
            });
        }
        (a, b, c, d) = (a + 1, b + 1, c - 1, d - 1);
    }
    None
}

/// A projector frame showing camera-space values `want` (per camera pixel, `None`: nothing)
/// through the decoded map; projector pixels no camera pixel reached take their nearest
/// reached neighbour within a few pixels, else black.
fn warp(corr: &Correspondence, want: impl Fn(usize) -> Option<f64>) -> ProjectorImage {
    let (w, h) = (corr.projector_width, corr.projector_height);
    let mut sum = vec![0.0f64; (w * h) as usize];
    let mut count = vec![0u32; (w * h) as usize];
    for (i, m) in corr.map.iter().enumerate() {
        if let (Some((x, y)), Some(v)) = (m, want(i))
            && *x < w
            && *y < h
        {
            let j = (y * w + x) as usize;
            sum[j] += v;
            count[j] += 1;
        }
    }
    let mut value: Vec<Option<f64>> = sum
        .iter()
        .zip(&count)
        .map(|(s, &c)| (c > 0).then(|| s / f64::from(c)))
        .collect();
    // Fill the holes between reached pixels (the projector is finer than the camera).
    for _ in 0..4 {
        let prev = value.clone();
        for y in 0..h {
            for x in 0..w {
                let j = (y * w + x) as usize;
                if prev[j].is_some() {
                    continue;
                }
                let mut acc = (0.0, 0);
                for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                    let (nx, ny) = (i64::from(x) + dx, i64::from(y) + dy);
                    if nx >= 0
                        && ny >= 0
                        && nx < i64::from(w)
                        && ny < i64::from(h)
                        && let Some(v) = prev[(ny as u32 * w + nx as u32) as usize]
                    {
                        acc = (acc.0 + v, acc.1 + 1);
                    }
                }
                if acc.1 > 0 {
                    value[j] = Some(acc.0 / f64::from(acc.1));
                }
            }
        }
    }
    ProjectorImage {
        width: w,
        height: h,
        pixels: value
            .iter()
            .map(|v| {
                let v = v.unwrap_or(0.0).clamp(0.0, 1.0) as f32;
                [v, v, v]
            })
            .collect(),
    }
}

fn lum(c: &Capture) -> Vec<f64> {
    c.pixels
        .iter()
        .map(|p| luminance(LinearRgb(p.map(f64::from))))
        .collect()
}

/// One LED preset and the luminaires' result for it.
#[derive(Debug, Clone, Copy)]
pub struct Lighting<'a> {
    pub preset: usize,
    pub name: &'a str,
    pub x: &'a [LinearRgb],
    /// Per-pixel shading gains per room projector (empty: the nodes' light as it is).
    pub gains: &'a [Option<roomlight_calib::shading::Gains>],
}

/// Runs projection mapping and the contrast measurements under `lightings` (the first for the
/// textures on the bust and the pictures; every one for the board's ANSI contrast), `room` the
/// calibrated room; then the board's ANSI contrast under projector lighting for each of
/// `tradeoff` (one capture each, after every other, so the rest sees the same noise with or
/// without them). Writes its images into `dir`.
pub fn run<'a>(
    room: &Room,
    cal: &Calibrated,
    lightings: &[Lighting<'a>],
    tradeoff: &[Lighting<'a>],
    seed: u64,
    dir: &Path,
    mut say: impl FnMut(String),
) -> Result<PmResult> {
    let base = room.scene();
    let first = *lightings
        .first()
        .context("projection mapping: no lighting to measure")?;
    let texture_k = base
        .projectors
        .iter()
        .position(|p| p.role == ProjectorRole::Texture)
        .with_context(|| format!("scene {} has no texture projector", base.name))?;
    let board_regions = board_regions(room, cal)?;
    let mut result = PmResult {
        ansi_contrast: [0.0; 3],
        ansi_by_preset: Vec::new(),
        linear: Vec::new(),
        rms_contrast: Vec::new(),
        images: Vec::new(),
        decoded_share: 0.0,
        tradeoff_ansi: Vec::new(),
    };
    let lights = Lights { cal, texture_k };
    // The board's nodes weigh every projector pixel (3 MB a node in the lab): they go once
    // its view has its sparse frames, before the texture projector is decoded on it.
    let mut board_regions: Option<Vec<NodeRegion>> = Some(board_regions);
    for board in [true, false] {
        // What the board's view freed goes back before the bust's view is built.
        if !board {
            crate::heap::release_free();
        }
        let eval = Room::build(evaluation_scene(base, board, false)?)
            .context("building the evaluation view")?;
        let luminaires = if board {
            let regions = board_regions
                .take()
                .context("the board's evaluation view is built once")?;
            FrameBuilder::new(&eval, &regions, lights.cal.responses.clone())?
        } else {
            FrameBuilder::new(&eval, &lights.cal.regions, lights.cal.responses.clone())?
        };
        let mut view = View::new(&eval, &lights, luminaires, first, seed)?;
        if board {
            board_contrast(&mut view, lightings, dir, &mut result, &mut say)?;
            for lighting in tradeoff {
                view.lighting = *lighting;
                let ansi = checker_ansi(&mut view, 2)?.0;
                result.tradeoff_ansi.push(ansi);
            }
            view.lighting = first;
        } else {
            bust_contrast(&mut view, dir, &mut result, &mut say)?;
        }
    }
    Ok(result)
}

/// The luminaires' nodes with the contrast board in place of the target: black on the board
/// as the room camera sees it and on the target the calibration kept dark. The correspondences
/// were decoded with the target in place, so the projector pixels that fell on it are known only
/// through its camera pixels; with the target gone they fly on and land on the board behind
/// it, wherever a luminaire looks from another side than the camera. Keeping the board's own
/// mask alone left them lit (issue 22 item 3: on the lab's paper preset the direct light on the
/// board doubled from the dark-target weight 0 to 10, and the board's contrast dipped while the
/// target darkened; docs/results.md).
pub fn board_regions(room: &Room, cal: &Calibrated) -> Result<Vec<NodeRegion>> {
    let board_room = Room::build(evaluation_scene(room.scene(), true, true)?)
        .context("building the room with the contrast board")?;
    let mask: Vec<bool> = board_room
        .pixels()
        .iter()
        .zip(room.pixels())
        .map(|(board, target)| board.target || target.target)
        .collect();
    // Only its mask is needed: the room goes before the regions are placed. Kept, it raised
    // the full demo's peak from 791 to 860 MB (2026-11-28, 03:13 and 03:22 UTC).
    drop(board_room);
    cal.regions_with_mask(room, &mask)
}

/// What every evaluation view lights the room with: the calibration, and which projector
/// carries the texture.
struct Lights<'a> {
    cal: &'a Calibrated,
    texture_k: usize,
}

/// One evaluation camera's view (board or bust) with the texture projector decoded onto it;
/// its noise is drawn in the same order as the captures are taken.
struct View<'a> {
    eval: &'a Room,
    lights: &'a Lights<'a>,
    /// The lighting the view is under now.
    lighting: Lighting<'a>,
    luminaires: FrameBuilder,
    noise: CameraNoise,
    corr: Correspondence,
    /// The target's camera pixels.
    mask: Vec<bool>,
    width: u32,
    /// Share of the target's camera pixels the decode reached.
    share: f64,
}

impl<'a> View<'a> {
    /// The view of `eval` lit through `luminaires` (their frames, texture projector black),
    /// with the texture projector decoded onto it.
    fn new(
        eval: &'a Room,
        lights: &'a Lights<'a>,
        luminaires: FrameBuilder,
        lighting: Lighting<'a>,
        seed: u64,
    ) -> Result<Self> {
        let mut noise = CameraNoise::with_seed(eval, seed);
        let corr = decode_texture(eval, lights.texture_k, &mut noise)?;
        let mask: Vec<bool> = eval.pixels().iter().map(|p| p.target).collect();
        let width = eval.scene().camera.resolution[0];
        let reached = mask
            .iter()
            .zip(&corr.map)
            .filter(|(m, c)| **m && c.is_some())
            .count();
        let share = reached as f64 / mask.iter().filter(|m| **m).count().max(1) as f64;
        Ok(Self {
            eval,
            lights,
            lighting,
            luminaires,
            noise,
            corr,
            mask,
            width,
            share,
        })
    }

    /// The frames of a lighting (dark, LED, projector) with `img` on the texture projector.
    fn with_texture(&self, condition: usize, img: ProjectorImage) -> Vec<Frame> {
        let mut frames = match condition {
            2 => self
                .luminaires
                .frames_shaded(self.lighting.x, self.lighting.gains),
            _ => vec![Frame::Black; self.eval.projectors().len()],
        };
        frames[self.lights.texture_k] = Frame::Linear(img);
        frames
    }

    fn shoot(&mut self, frames: &[Frame], condition: usize) -> Result<Capture> {
        let leds = (condition == 1).then_some(self.lighting.preset);
        Ok(self.noise.expose(&self.eval.render(frames, leds)?))
    }
}

/// The 4×4 checker projected on the board (white at the top left) under lighting `condition`
/// of the view's lighting: its ANSI contrast and the capture.
fn checker_ansi(view: &mut View<'_>, condition: usize) -> Result<(f64, Capture)> {
    let width = view.width;
    let Some(rect) = inner_rect(&view.mask, width) else {
        bail!("the board is not visible to the evaluation camera");
    };
    let cell = |i: usize| -> Option<f64> {
        let (u, v) = ((i as u32 % width) as f64, (i as u32 / width) as f64);
        let (s, t) = ((u - rect.x) / rect.width, (v - rect.y) / rect.height);
        ((0.0..1.0).contains(&s) && (0.0..1.0).contains(&t)).then(|| {
            let (a, b) = ((s * 4.0) as u32, (t * 4.0) as u32);
            if (a + b) % 2 == 0 { 1.0 } else { 0.0 }
        })
    };
    let mask = &view.mask;
    let checker = warp(&view.corr, |i| if mask[i] { cell(i) } else { None });
    let frames = view.with_texture(condition, checker);
    let cap = view.shoot(&frames, condition)?;
    let l: Vec<f32> = lum(&cap).iter().map(|&v| v as f32).collect();
    let a = ansi_contrast(
        GrayImage {
            width: cap.width as usize,
            height: cap.height as usize,
            pixels: &l,
        },
        rect,
        true,
    )?;
    Ok((a.ratio, cap))
}

/// ANSI contrast of a 4×4 checker projected on the board in the dark, then under each
/// lighting's LEDs and projectors (pictures of the first only).
fn board_contrast<'a>(
    view: &mut View<'a>,
    lightings: &[Lighting<'a>],
    dir: &Path,
    result: &mut PmResult,
    say: &mut impl FnMut(String),
) -> Result<()> {
    let mut dark = 0.0;
    for (k, lighting) in lightings.iter().enumerate() {
        view.lighting = *lighting;
        let mut ansi = [dark; 3];
        for (condition, label) in CONDITIONS.iter().enumerate() {
            // The dark room is the same for every lighting: measured once.
            if condition == 0 && k > 0 {
                continue;
            }
            let (ratio, cap) = checker_ansi(view, condition)?;
            ansi[condition] = ratio;
            if condition == 0 {
                dark = ratio;
            }
            if k == 0 {
                let file = format!("pm-checker-{label}.png");
                result.linear.push(save(&cap, dir, &file)?);
                result
                    .images
                    .push((file, format!("checker, {label}: ANSI {ratio:.0}:1")));
            }
        }
        if k == 0 {
            result.ansi_contrast = ansi;
        }
        result
            .ansi_by_preset
            .push((lighting.name.to_string(), ansi));
    }
    view.lighting = lightings[0];
    say(format!(
        "ANSI contrast on the board: dark {:.0}:1, LED {:.0}:1, projector lighting {:.0}:1",
        result.ansi_contrast[0], result.ansi_contrast[1], result.ansi_contrast[2]
    ));
    Ok(())
}

/// Projection mapping on the bust: RMS contrast of each compensated texture under each
/// lighting.
fn bust_contrast(
    view: &mut View<'_>,
    dir: &Path,
    result: &mut PmResult,
    say: &mut impl FnMut(String),
) -> Result<()> {
    result.decoded_share = view.share;
    let comp = Compensation::measure(view)?;
    for condition in 0..3 {
        let rms = textures_under(
            view,
            &comp,
            condition,
            dir,
            &mut result.images,
            &mut result.linear,
        )?;
        for (t, r) in TEXTURES.iter().zip(rms) {
            match result.rms_contrast.iter_mut().find(|(n, _)| n == t) {
                Some((_, v)) => v[condition] = r,
                None => {
                    let mut v = [0.0; 3];
                    v[condition] = r;
                    result.rms_contrast.push(((*t).to_string(), v));
                }
            }
        }
    }
    say(format!(
        "projection mapping on the bust ({:.0}% of it decoded): RMS contrast {}",
        100.0 * view.share,
        result
            .rms_contrast
            .iter()
            .map(|(t, v)| format!("{t} {:.2}/{:.2}/{:.2}", v[0], v[1], v[2]))
            .collect::<Vec<_>>()
            .join(", ")
    ));
    Ok(())
}

/// Compensation: the gain of the texture projector per camera pixel (white − black in the
/// dark); the texture asks for k·T + the brightest ambient, so every pixel can reach it where
/// the gain allows.
struct Compensation {
    gain: Vec<f64>,
    /// The 10th percentile of the gain on the bust.
    k: f64,
    /// The bust's bounding box in the camera: x0, y0, x1, y1.
    bounds: (u32, u32, u32, u32),
    black: ProjectorImage,
}

impl Compensation {
    fn measure(view: &mut View<'_>) -> Result<Self> {
        let corr = &view.corr;
        let white = ProjectorImage {
            width: corr.projector_width,
            height: corr.projector_height,
            pixels: vec![[1.0; 3]; (corr.projector_width * corr.projector_height) as usize],
        };
        let black = ProjectorImage {
            pixels: vec![[0.0; 3]; white.pixels.len()],
            ..white.clone()
        };
        let frames = view.with_texture(0, white);
        let lit = lum(&view.shoot(&frames, 0)?);
        let frames = view.with_texture(0, black.clone());
        let dark = lum(&view.shoot(&frames, 0)?);
        let gain: Vec<f64> = lit
            .iter()
            .zip(&dark)
            .map(|(a, b)| (a - b).max(0.0))
            .collect();
        let bounds = bounds(&view.mask, view.width)
            .context("the bust is not visible to the evaluation camera")?;
        let mut g: Vec<f64> = gain
            .iter()
            .zip(&view.mask)
            .filter(|(_, m)| **m)
            .map(|(g, _)| *g)
            .collect();
        let k = percentile(&mut g, 0.1);
        Ok(Self {
            gain,
            k,
            bounds,
            black,
        })
    }
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(((v.len() as f64 - 1.0) * q) as usize)
        .copied()
        .unwrap_or(0.0)
}

/// Every texture, compensated for this lighting's ambient, captured and saved; their RMS
/// contrasts on the bust in `TEXTURES` order.
fn textures_under(
    view: &mut View<'_>,
    comp: &Compensation,
    condition: usize,
    dir: &Path,
    images: &mut Vec<(String, String)>,
    linear: &mut Vec<(String, f64)>,
) -> Result<Vec<f64>> {
    let (x0, y0, x1, y1) = comp.bounds;
    let (k, gain, width) = (comp.k, &comp.gain, view.width);
    let frames = view.with_texture(condition, comp.black.clone());
    let ambient = lum(&view.shoot(&frames, condition)?);
    let mut a: Vec<f64> = ambient
        .iter()
        .zip(&view.mask)
        .filter(|(_, m)| **m)
        .map(|(a, _)| *a)
        .collect();
    let floor = percentile(&mut a, 0.9);
    let mut rms = Vec::new();
    for name in TEXTURES {
        let mask = &view.mask;
        let img = warp(&view.corr, |i| {
            if !mask[i] {
                return None;
            }
            let (u, v) = (i as u32 % width, i as u32 / width);
            let s = f64::from(u - x0) / f64::from((x1 - x0).max(1));
            let t = f64::from(v - y0) / f64::from((y1 - y0).max(1));
            let want = k * texture(name, s, t) + floor;
            // Zero gain (unreached): nothing to do there.
            (gain[i] > 0.0).then(|| (want - ambient[i]) / gain[i])
        });
        let frames = view.with_texture(condition, img);
        let cap = view.shoot(&frames, condition)?;
        let l: Vec<f64> = lum(&cap)
            .iter()
            .zip(&view.mask)
            .filter(|(_, m)| **m)
            .map(|(l, _)| *l)
            .collect();
        rms.push(rms_contrast(&l)?);
        let file = format!("pm-{name}-{}.png", CONDITIONS[condition]);
        linear.push(save(&cap, dir, &file)?);
        images.push((file, format!("{name}, {}", CONDITIONS[condition])));
    }
    Ok(rms)
}

/// Writes `c` for viewing (one exposure for every projection-mapping image, so they compare by
/// eye: 1.0 at full scale) and as linear 16-bit; returns the linear file and its scale.
fn save(c: &Capture, dir: &Path, file: &str) -> Result<(String, f64)> {
    use crate::report::png::{srgb8, write_linear16, write_srgb8_image};
    write_srgb8_image(&dir.join(file), &srgb8(c, 1.0)?)?;
    let linear = file.replace(".png", ".linear16.png");
    let scale = write_linear16(&dir.join(&linear), c)?;
    Ok((linear, scale))
}
