//! The simulated room: precomputed light transport from every projector and LED panel to the
//! camera pixels, the chart patches and the radiosity elements; `render` turns projector frames
//! and an LED preset into a linear camera capture.

use crate::geometry::{EPS, Geometry, V3};
use crate::optics::{Fisheye, Light, Projector};
use crate::radiosity::Radiosity;
use crate::scene::{Scene, SceneError};
use rayon::prelude::*;
use roomlight_core::LinearRgb;

mod basis;
mod buffers;
mod capture;
mod direct;
mod noise;
mod probes;
mod subset;
mod summed_area;

pub use basis::{NodeBasis, NodeRegion};
pub use capture::{Capture, PngEncoding};
pub use noise::CameraNoise;
pub use subset::PixelSubset;
use summed_area::SummedArea;

/// What a projector shows: code values in `[0, 1]` per channel (not linear light).
#[derive(Debug, Clone, PartialEq)]
pub enum Frame {
    /// Every pixel at code 0.
    Black,
    /// Every pixel at the same code (the fast path).
    Uniform([f32; 3]),
    /// A full image of the projector's resolution.
    Image(ProjectorImage),
    /// An image of linear light shares in `[0, 1]` (a perfectly linearised projector: the
    /// response curve is bypassed). For ground truth and node bases, not for the real system.
    Linear(ProjectorImage),
}

/// A projector image: row-major codes in `[0, 1]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ProjectorImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width · height` RGB codes.
    pub pixels: Vec<[f32; 3]>,
}

/// Errors of the simulator.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// The scene is wrong.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// Frames do not match the projectors.
    #[error("frame for projector {projector}: {problem}")]
    Frame { projector: String, problem: String },
    /// An unknown preset or projector name.
    #[error("no {kind} named {name:?} in this scene")]
    Unknown { kind: &'static str, name: String },
    /// A camera pixel index beyond the image.
    #[error("camera pixel {pixel} is outside the camera's {count} pixels")]
    PixelOutside { pixel: u32, count: usize },
    /// A file could not be written.
    #[error("writing {path}: {message}")]
    Io { path: String, message: String },
}

/// Light transport from one projector to a set of probes.
#[derive(Debug, Clone, Default)]
struct ProjectorMap {
    /// `(probe, projector pixel, factor)`: irradiance at the probe per unit pixel light.
    entries: Vec<(u32, u32, f32)>,
    /// `(probe, [x0, y0, x1, y1], factor)`: irradiance at the probe per unit of the mean light
    /// over a rectangle of pixels (half-open): a radiosity element's sample integrates the
    /// frame over the patch of surface it stands for, as a real wall does, instead of taking
    /// one pixel (fine stripes would alias into its reflected light).
    boxes: Vec<(u32, [u32; 4], f32)>,
    /// Sum of the factors per probe: the uniform-frame fast path.
    white: Vec<f32>,
}

/// Points where irradiance is needed (camera pixels, elements, chart patches), each the mean of
/// one or more surface samples.
#[derive(Debug, Clone, Default)]
struct Probes {
    albedo: Vec<LinearRgb>,
    /// Bilinear weights into the elements, for indirect light.
    interp: Vec<[(u32, f32); 4]>,
    projectors: Vec<ProjectorMap>,
    /// Per light, the geometric factor per probe (visibility included).
    lights: Vec<Vec<f32>>,
}

/// One surface sample of a probe: `(probe, point, normal, weight, cell)`, where `cell` holds
/// the corners of the patch of surface the sample stands for when its light is integrated
/// over that patch (radiosity elements), `None` for a point sample.
type Sample = (u32, V3, V3, f32, Option<[V3; 4]>);

/// What a camera pixel sees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelInfo {
    /// The world point, if the pixel sees one.
    pub point: Option<[f32; 3]>,
    /// The face it lies on.
    pub face: Option<usize>,
    /// True on the projection-mapping target.
    pub target: bool,
    /// `(chart, patch)` where the pixel sees a chart patch (patch `None` on the chart's frame).
    pub chart: Option<(usize, Option<usize>)>,
}

/// The simulated room, with all its precomputation.
#[derive(Debug)]
pub struct Room {
    scene: Scene,
    geometry: Geometry,
    projectors: Vec<Projector>,
    lights: Vec<Light>,
    camera: Fisheye,
    radiosity: Option<Radiosity>,
    pixels: Vec<PixelInfo>,
    camera_probes: Probes,
    element_probes: Probes,
    patch_probes: Probes,
    /// Per-pixel buffers of the renders, kept from one to the next.
    buffers: buffers::Buffers,
}

/// Radiosity stops when no element's radiosity changes by more than this share of the largest.
pub const RADIOSITY_TOLERANCE: f64 = 1e-5;

/// Probes per chart patch (a 4×4 grid over its inner half).
const PATCH_SAMPLES: usize = 16;

/// Light-panel samples per side, and visibility rays per light and probe sample.
const LIGHT_GRID: usize = 4;

impl Room {
    /// Builds and precomputes a room from a validated scene.
    pub fn build(scene: Scene) -> Result<Self, SimError> {
        scene.validate_fields()?;
        let geometry = Geometry::build(&scene)?;
        let projectors: Vec<Projector> = scene.projectors.iter().map(Projector::new).collect();
        let lights: Vec<Light> = scene
            .lights
            .iter()
            .map(|l| Light::new(l, LIGHT_GRID))
            .collect();
        let camera = Fisheye::new(&scene.camera);
        let radiosity = scene
            .room
            .interreflection
            .then(|| Radiosity::build(&geometry, true));
        let (pixels, camera_probes) = probes::camera_view(&camera, &geometry);
        let mut room = Self {
            scene,
            geometry,
            projectors,
            lights,
            camera,
            radiosity,
            pixels,
            camera_probes: Probes::default(),
            element_probes: Probes::default(),
            patch_probes: Probes::default(),
            buffers: buffers::Buffers::default(),
        };
        room.camera_probes = room.probes(camera_probes);
        room.element_probes = room.probes(probes::element_samples(&room.geometry));
        room.patch_probes = room.probes(probes::patch_samples(&room.geometry));
        Ok(room)
    }

    /// The scene this room was built from.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The geometry (faces, elements, charts).
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    /// The projectors' optics, in scene order.
    pub fn projectors(&self) -> &[Projector] {
        &self.projectors
    }

    /// The camera model.
    pub fn camera(&self) -> &Fisheye {
        &self.camera
    }

    /// The radiosity solver (`None` with inter-reflection off).
    pub fn radiosity(&self) -> Option<&Radiosity> {
        self.radiosity.as_ref()
    }

    /// What each camera pixel sees.
    pub fn pixels(&self) -> &[PixelInfo] {
        &self.pixels
    }

    /// Each chart's outer corners in camera pixels (top-left, top-right, bottom-right,
    /// bottom-left), as a person would click them once in the camera image; `None` for a chart
    /// whose corner lies outside the camera's view.
    pub fn chart_corners_px(&self) -> Vec<Option<[[f64; 2]; 4]>> {
        self.geometry
            .charts
            .iter()
            .map(|c| {
                let (hw, hh) = (0.5 * c.width, 0.5 * c.height);
                let pts = [
                    c.center - c.right * hw + c.up * hh,
                    c.center + c.right * hw + c.up * hh,
                    c.center + c.right * hw - c.up * hh,
                    c.center - c.right * hw - c.up * hh,
                ];
                let mut out = [[0.0; 2]; 4];
                for (o, p) in out.iter_mut().zip(pts) {
                    let (u, v) = self.camera.project(p)?;
                    *o = [f64::from(u), f64::from(v)];
                }
                Some(out)
            })
            .collect()
    }

    /// Number of chart patches (24 per chart, chart-major).
    pub fn patches(&self) -> usize {
        self.geometry.charts.len() * 24
    }

    /// Index of a preset by name.
    pub fn preset(&self, name: &str) -> Result<usize, SimError> {
        self.scene
            .presets
            .iter()
            .position(|p| p.name == name)
            .ok_or_else(|| SimError::Unknown {
                kind: "preset",
                name: name.to_string(),
            })
    }

    /// Index of a projector by name.
    pub fn projector(&self, name: &str) -> Result<usize, SimError> {
        self.projectors
            .iter()
            .position(|p| p.name == name)
            .ok_or_else(|| SimError::Unknown {
                kind: "projector",
                name: name.to_string(),
            })
    }

    fn check_frames(&self, frames: &[Frame]) -> Result<(), SimError> {
        if frames.len() != self.projectors.len() {
            return Err(SimError::Frame {
                projector: "(all)".into(),
                problem: format!(
                    "{} frames for {} projectors",
                    frames.len(),
                    self.projectors.len()
                ),
            });
        }
        for (frame, p) in frames.iter().zip(&self.projectors) {
            let bad = |problem: String| SimError::Frame {
                projector: p.name.clone(),
                problem,
            };
            match frame {
                Frame::Black => {}
                Frame::Uniform(code) => {
                    if code.iter().any(|v| !v.is_finite()) {
                        return Err(bad(format!("code {code:?} is not finite")));
                    }
                }
                Frame::Image(img) | Frame::Linear(img) => {
                    if img.width != p.pinhole.width || img.height != p.pinhole.height {
                        return Err(bad(format!(
                            "image is {}x{}, the projector is {}x{}",
                            img.width, img.height, p.pinhole.width, p.pinhole.height
                        )));
                    }
                    if img.pixels.len() != (img.width * img.height) as usize {
                        return Err(bad(format!(
                            "{} pixels for {}x{}",
                            img.pixels.len(),
                            img.width,
                            img.height
                        )));
                    }
                    if !img.pixels.as_flattened().iter().all(|v| v.is_finite()) {
                        return Err(bad("a pixel code is not finite".into()));
                    }
                }
            }
        }
        Ok(())
    }

    /// Direct irradiance on every probe of a set.
    fn direct(&self, probes: &Probes, frames: &[Frame], preset: Option<usize>) -> Vec<LinearRgb> {
        self.direct_sets(&[probes], frames, preset)
            .pop()
            .unwrap_or_default()
    }

    /// Indirect irradiance on the elements from their direct irradiance (zero with
    /// inter-reflection off).
    fn indirect(&self, element_direct: &[LinearRgb]) -> Vec<LinearRgb> {
        match &self.radiosity {
            Some(r) => r.solve(element_direct, RADIOSITY_TOLERANCE).indirect,
            None => vec![LinearRgb::ZERO; self.geometry.elements.len()],
        }
    }

    /// Direct irradiance on the elements and on each probe set, in one pass over the frames.
    fn direct_with_elements(
        &self,
        sets: &[&Probes],
        frames: &[Frame],
        preset: Option<usize>,
    ) -> (Vec<LinearRgb>, Vec<Vec<LinearRgb>>) {
        if self.radiosity.is_none() {
            return (Vec::new(), self.direct_sets(sets, frames, preset));
        }
        let mut all = vec![&self.element_probes];
        all.extend_from_slice(sets);
        let mut direct = self.direct_sets(&all, frames, preset);
        let elements = direct.remove(0);
        (elements, direct)
    }

    /// Camera value of each probe: `exposure · ρ/π · (E_direct + H)`.
    fn values(
        &self,
        probes: &Probes,
        direct: &[LinearRgb],
        indirect: &[LinearRgb],
    ) -> Vec<LinearRgb> {
        let k = self.scene.camera.exposure / std::f64::consts::PI;
        direct
            .par_iter()
            .with_min_len(4096)
            .zip(&probes.albedo)
            .zip(&probes.interp)
            .map(|((&e, &rho), weights)| {
                let mut total = e;
                for &(el, w) in weights {
                    if w > 0.0 {
                        total += indirect[el as usize] * f64::from(w);
                    }
                }
                rho.hadamard(total) * k
            })
            .collect()
    }

    /// The capture and the chart patches from one radiosity solve.
    fn render_with_patches(
        &self,
        frames: &[Frame],
        preset: Option<usize>,
    ) -> Result<(Vec<[f32; 3]>, Vec<LinearRgb>), SimError> {
        self.check_frames(frames)?;
        let (elements, direct) =
            self.direct_with_elements(&[&self.camera_probes, &self.patch_probes], frames, preset);
        let indirect = self.indirect(&elements);
        let capture = to_f32(self.values(&self.camera_probes, &direct[0], &indirect));
        Ok((
            capture,
            Self::aggregate_patches(&self.values(&self.patch_probes, &direct[1], &indirect)).0,
        ))
    }

    /// Direct irradiance on every radiosity element (each the mean over its surface) for these
    /// frames and LED preset: the light inter-reflection starts from.
    pub fn element_irradiance(
        &self,
        frames: &[Frame],
        preset: Option<usize>,
    ) -> Result<Vec<LinearRgb>, SimError> {
        self.check_frames(frames)?;
        Ok(self.direct(&self.element_probes, frames, preset))
    }

    /// The noiseless capture for these frames (one per projector) and LED preset.
    pub fn render(&self, frames: &[Frame], preset: Option<usize>) -> Result<Capture, SimError> {
        self.check_frames(frames)?;
        let (elements, direct) = self.direct_with_elements(&[&self.camera_probes], frames, preset);
        let indirect = self.indirect(&elements);
        Ok(Capture {
            width: self.camera.width,
            height: self.camera.height,
            pixels: to_f32(self.values(&self.camera_probes, &direct[0], &indirect)),
        })
    }

    /// Ground truth: the noiseless camera value of every chart patch (chart-major, 24 each),
    /// averaged over the inner half of the patch.
    pub fn patch_values(
        &self,
        frames: &[Frame],
        preset: Option<usize>,
    ) -> Result<Vec<LinearRgb>, SimError> {
        Ok(self.patch_values_and_spread(frames, preset)?.0)
    }

    /// Ground truth: each patch's mean and the spread of the light over its inner half,
    /// `(max − min)/mean` per channel (0 where the mean is 0). A large spread means an edge
    /// (shadow, frustum or node boundary) crosses the patch, where "the patch value" depends on
    /// where one looks.
    pub fn patch_values_and_spread(
        &self,
        frames: &[Frame],
        preset: Option<usize>,
    ) -> Result<(Vec<LinearRgb>, Vec<LinearRgb>), SimError> {
        self.check_frames(frames)?;
        let (elements, direct) = self.direct_with_elements(&[&self.patch_probes], frames, preset);
        let indirect = self.indirect(&elements);
        let samples = self.values(&self.patch_probes, &direct[0], &indirect);
        Ok(Self::aggregate_patches(&samples))
    }

    fn aggregate_patches(samples: &[LinearRgb]) -> (Vec<LinearRgb>, Vec<LinearRgb>) {
        samples
            .chunks(PATCH_SAMPLES)
            .map(|chunk| {
                let mean = chunk.iter().fold(LinearRgb::ZERO, |a, v| a + *v)
                    * (1.0 / PATCH_SAMPLES as f64);
                let spread = LinearRgb(std::array::from_fn(|c| {
                    let (lo, hi) = chunk
                        .iter()
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                            (lo.min(v[c]), hi.max(v[c]))
                        });
                    if mean[c] > 0.0 {
                        (hi - lo) / mean[c]
                    } else {
                        0.0
                    }
                }));
                (mean, spread)
            })
            .unzip()
    }

    /// Ground truth: the projector pixel each camera pixel sees through the projector's lens
    /// centre (the true correspondence), where it is lit directly.
    pub fn true_correspondence(&self, projector: usize) -> Vec<Option<u32>> {
        let p = &self.projectors[projector];
        self.pixels
            .iter()
            .map(|info| {
                let point = V3::from_array(info.point?);
                let uv = p.pinhole.project(point)?;
                let px = p.pinhole.pixel(uv)?;
                let to_lens = (p.pinhole.position - point).normalize_or_zero();
                self.geometry
                    .visible(p.pinhole.position, point + to_lens * EPS)
                    .then_some(px)
            })
            .collect()
    }

    /// Ground truth: per camera pixel, the direct irradiance from one projector per unit pixel
    /// light (its geometric factor: cosine, distance, visibility, lens samples). Zero where the
    /// projector does not light the surface the pixel sees.
    pub fn direct_factor(&self, projector: usize) -> &[f32] {
        &self.camera_probes.projectors[projector].white
    }

    /// Ground truth: the albedo of the surface each camera pixel sees (chart patches included).
    pub fn pixel_albedo(&self) -> &[LinearRgb] {
        &self.camera_probes.albedo
    }

    /// Ground truth: the mean direct irradiance on the target's visible surface from one
    /// projector showing `frame` (all others black, no LEDs, no inter-reflection).
    pub fn target_irradiance(
        &self,
        projector: usize,
        frame: &Frame,
    ) -> Result<LinearRgb, SimError> {
        let mut frames = vec![Frame::Black; self.projectors.len()];
        frames[projector] = frame.clone();
        self.check_frames(&frames)?;
        let direct = self.direct_from(&self.camera_probes, projector, frame);
        let (mut sum, mut n) = (LinearRgb::ZERO, 0usize);
        for (info, e) in self.pixels.iter().zip(direct) {
            if info.target {
                sum += e;
                n += 1;
            }
        }
        // No target pixel in view: the mean is undefined; report zero light.
        Ok(if n > 0 {
            sum * (1.0 / n as f64)
        } else {
            LinearRgb::ZERO
        })
    }

    /// Ground truth: the direct irradiance at any surface point (metres) with unit normal from
    /// one projector showing `frame`, with visibility.
    pub fn direct_irradiance_at(
        &self,
        projector: usize,
        frame: &Frame,
        point: [f32; 3],
        normal: [f32; 3],
    ) -> Result<LinearRgb, SimError> {
        let p = self
            .projectors
            .get(projector)
            .ok_or_else(|| SimError::Unknown {
                kind: "projector",
                name: projector.to_string(),
            })?;
        let mut frames = vec![Frame::Black; self.projectors.len()];
        frames[projector] = frame.clone();
        self.check_frames(&frames)?;
        let (point, normal) = (
            V3::from_array(point),
            V3::from_array(normal).normalize_or_zero(),
        );
        let lifted = point + normal * EPS;
        let mut e = LinearRgb::ZERO;
        p.footprint(point, normal, |lens, px, factor| {
            if self.geometry.visible(lens, lifted) {
                let light = match frame {
                    Frame::Black => p.light([0.0; 3]),
                    Frame::Uniform(c) => p.light(*c),
                    Frame::Image(img) => p.light(img.pixels[px as usize]),
                    Frame::Linear(img) => p.light_linear(img.pixels[px as usize]),
                };
                e += light * f64::from(factor);
            }
        });
        Ok(e)
    }

    fn direct_from(&self, probes: &Probes, projector: usize, frame: &Frame) -> Vec<LinearRgb> {
        let mut frames = vec![Frame::Black; self.projectors.len()];
        frames[projector] = frame.clone();
        let mut e = self.direct(probes, &frames, None);
        // Remove the other projectors' native black.
        for (k, p) in self.projectors.iter().enumerate() {
            if k != projector {
                let light = p.light([0.0; 3]);
                for (ei, &w) in e.iter_mut().zip(&probes.projectors[k].white) {
                    *ei -= light * f64::from(w);
                }
            }
        }
        e
    }
}

/// Linear camera values as the capture's f32 pixels.
fn to_f32(values: Vec<LinearRgb>) -> Vec<[f32; 3]> {
    values
        .into_iter()
        .map(|v| [v[0] as f32, v[1] as f32, v[2] as f32])
        .collect()
}
