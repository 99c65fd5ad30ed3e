//! Light sources and the camera: pinhole and thin-lens projectors, LED panels with a colour
//! temperature, and the equidistant fisheye camera.

use crate::geometry::{V3, dir, mm};
use crate::scene::{CameraSpec, LightSpec, ProjectorKind, ProjectorSpec};
use roomlight_core::LinearRgb;

/// Linear sRGB (luminance 1) of a blackbody at `kelvin` (1667–25000 K), from the cubic fits of
/// the Planckian locus by Kim et al. (2002) and the sRGB matrix. Negative channels clip to 0.
pub fn cct_to_linear_rgb(kelvin: f64) -> LinearRgb {
    let t = kelvin.clamp(1667.0, 25000.0);
    let (t2, t3) = (t * t, t * t * t);
    let x = if t <= 4000.0 {
        -0.266_123_9e9 / t3 - 0.234_358_9e6 / t2 + 0.877_695_6e3 / t + 0.179_910
    } else {
        -3.025_846_9e9 / t3 + 2.107_037_9e6 / t2 + 0.222_634_7e3 / t + 0.240_390
    };
    let (x2, x3) = (x * x, x * x * x);
    let y = if t <= 2222.0 {
        -1.106_381_4 * x3 - 1.348_110_20 * x2 + 2.185_558_32 * x - 0.202_196_83
    } else if t <= 4000.0 {
        -0.954_947_6 * x3 - 1.374_185_93 * x2 + 2.091_370_15 * x - 0.167_488_67
    } else {
        3.081_758_0 * x3 - 5.873_386_70 * x2 + 3.751_129_97 * x - 0.370_014_83
    };
    // xyY with Y = 1 → XYZ → linear sRGB (IEC 61966-2-1 matrix).
    let (cx, cy, cz) = (x / y, 1.0, (1.0 - x - y) / y);
    LinearRgb([
        (3.2406 * cx - 1.5372 * cy - 0.4986 * cz).max(0.0),
        (-0.9689 * cx + 1.8758 * cy + 0.0415 * cz).max(0.0),
        (0.0557 * cx - 0.2040 * cy + 1.0570 * cz).max(0.0),
    ])
}

/// A pinhole: pose and intrinsics in pixels (x right, y down, z forward).
#[derive(Debug, Clone, Copy)]
pub struct Pinhole {
    /// Centre of projection.
    pub position: V3,
    right: V3,
    down: V3,
    /// Optical axis.
    pub forward: V3,
    focal_px: f32,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
}

impl Pinhole {
    fn new(position: V3, look_at: V3, up: V3, fov_deg: f64, width: u32, height: u32) -> Self {
        let forward = (look_at - position).normalize();
        let right = forward.cross(up).normalize();
        let down = forward.cross(right);
        let focal_px = (0.5 * width as f32) / ((fov_deg as f32).to_radians() * 0.5).tan();
        Self {
            position,
            right,
            down,
            forward,
            focal_px,
            width,
            height,
        }
    }

    /// Image coordinates (pixel centres at +0.5) of a point in front, or `None` behind.
    pub fn project(&self, p: V3) -> Option<(f32, f32)> {
        let d = p - self.position;
        let z = d.dot(self.forward);
        if z <= 1e-6 {
            return None;
        }
        Some((
            0.5 * self.width as f32 + self.focal_px * d.dot(self.right) / z,
            0.5 * self.height as f32 + self.focal_px * d.dot(self.down) / z,
        ))
    }

    /// The pixel index containing image coordinates, if inside the image.
    pub fn pixel(&self, (u, v): (f32, f32)) -> Option<u32> {
        if u >= 0.0 && v >= 0.0 && u < self.width as f32 && v < self.height as f32 {
            Some(v as u32 * self.width + u as u32)
        } else {
            None
        }
    }

    /// Unit direction of the ray through image coordinates `(u, v)`.
    pub fn ray(&self, u: f32, v: f32) -> V3 {
        let x = (u - 0.5 * self.width as f32) / self.focal_px;
        let y = (v - 0.5 * self.height as f32) / self.focal_px;
        (self.forward + self.right * x + self.down * y).normalize()
    }
}

/// Steps of a projector's tabulated response curve per channel.
const CURVE_STEPS: usize = 4096;

/// A projector's response curve `code^γ` per channel, the way a projector holds it: a table
/// (4096 steps) read with linear interpolation, for `γ ≥ 1`. Exact at 0, at 1 and at every
/// step; between them within 2e-7 of the power for γ from 1.8 to 5 (the lab's are 2.1–2.3),
/// within 4e-6 of full light for any γ ≥ 1 (tested). A `γ` below 1 is steep near black and
/// keeps the power itself. Three powers a pixel were most of rendering a frame of codes.
#[derive(Clone)]
struct Curve {
    gamma: [f32; 3],
    tables: [Option<Vec<f32>>; 3],
}

impl std::fmt::Debug for Curve {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Curve(γ {:?}, {CURVE_STEPS} steps)", self.gamma)
    }
}

impl Curve {
    fn new(gamma: [f64; 3]) -> Self {
        Self {
            gamma: gamma.map(|g| g as f32),
            tables: gamma.map(|g| {
                (g >= 1.0).then(|| {
                    (0..=CURVE_STEPS)
                        .map(|i| (i as f64 / CURVE_STEPS as f64).powf(g) as f32)
                        .collect()
                })
            }),
        }
    }

    /// The light share of channel `c` at `code` (clipped to `[0, 1]`; NaN stays NaN).
    fn share(&self, c: usize, code: f32) -> f32 {
        let code = code.clamp(0.0, 1.0);
        let Some(table) = &self.tables[c] else {
            return code.powf(self.gamma[c]);
        };
        let x = code * CURVE_STEPS as f32;
        // `x` is in [0, STEPS]; the last step interpolates up to 1 exactly.
        let i = (x as usize).min(CURVE_STEPS - 1);
        let t = x - i as f32;
        table[i] + (table[i + 1] - table[i]) * t
    }
}

/// A projector's optics and response.
#[derive(Debug, Clone)]
pub struct Projector {
    /// Name in the scene.
    pub name: String,
    /// Geometry of the image (through the lens centre).
    pub pinhole: Pinhole,
    /// Lens sample points (one, the centre, for a standard projector).
    pub lens: Vec<V3>,
    /// Focus distance along the axis (large aperture only).
    pub focus: Option<f32>,
    black_level: f64,
    peak: LinearRgb,
    curve: Curve,
    mixing: Option<[[f64; 3]; 3]>,
    /// Standard or large aperture.
    pub kind: ProjectorKind,
}

impl Projector {
    /// Builds a projector from its (validated) description.
    pub fn new(spec: &ProjectorSpec) -> Self {
        let pinhole = Pinhole::new(
            mm(spec.position_mm),
            mm(spec.look_at_mm),
            dir(spec.up),
            spec.fov_deg,
            spec.resolution[0],
            spec.resolution[1],
        );
        let (lens, focus) = match spec.kind {
            ProjectorKind::Standard => (vec![pinhole.position], None),
            ProjectorKind::LargeAperture => {
                let radius = (spec.aperture_mm.unwrap_or(0.0) / 2000.0) as f32;
                let n = spec.lens_samples.unwrap_or(32).max(1) as usize;
                let samples = disk_samples(n)
                    .into_iter()
                    .map(|(a, b)| {
                        pinhole.position + (pinhole.right * a + pinhole.down * b) * radius
                    })
                    .collect();
                (
                    samples,
                    Some((spec.focus_mm.unwrap_or(1000.0) / 1000.0) as f32),
                )
            }
        };
        Self {
            name: spec.name.clone(),
            pinhole,
            lens,
            focus,
            black_level: spec.black_level,
            peak: LinearRgb(spec.peak),
            curve: Curve::new(spec.gamma),
            mixing: spec.mixing,
            kind: spec.kind,
        }
    }

    /// The light a pixel emits for a code value per channel: native black, response curve,
    /// primaries mixing, peak. In irradiance at 1 m on the axis.
    pub fn light(&self, code: [f32; 3]) -> LinearRgb {
        let linear = std::array::from_fn(|c| self.curve.share(c, code[c]));
        self.light_linear(linear)
    }

    /// The light of a perfectly linearised pixel: `share` of the way from native black to white
    /// per channel, then mixing and peak.
    pub fn light_linear(&self, share: [f32; 3]) -> LinearRgb {
        let mut lin = [0.0f64; 3];
        for c in 0..3 {
            lin[c] =
                self.black_level + (1.0 - self.black_level) * f64::from(share[c]).clamp(0.0, 1.0);
        }
        let mixed = match self.mixing {
            None => lin,
            Some(m) => std::array::from_fn(|r| (0..3).map(|c| m[r][c] * lin[c]).sum()),
        };
        LinearRgb(mixed).hadamard(self.peak)
    }

    /// True when the projector mixes its primaries (a channel's light reaches other channels).
    pub fn mixes(&self) -> bool {
        self.mixing.is_some()
    }

    /// For a surface point `p` with normal `n`, the projector pixels that light it and the
    /// geometric factor of each (irradiance per unit pixel light), ignoring visibility:
    /// `cos θ_surface / (d² cos³ α)` averaged over the lens samples (DESIGN §5).
    pub fn footprint(&self, p: V3, n: V3, mut visit: impl FnMut(V3, u32, f32)) {
        let per_sample = 1.0 / self.lens.len() as f32;
        for &l in &self.lens {
            let d = p - l;
            let dist2 = d.length_squared();
            if dist2 <= 1e-12 {
                continue;
            }
            let dist = dist2.sqrt();
            let cos_s = -n.dot(d) / dist;
            let cos_a = self.pinhole.forward.dot(d) / dist;
            if cos_s <= 0.0 || cos_a <= 1e-3 {
                continue;
            }
            // The ray from lens point l through p came from the display pixel whose image (through
            // the lens centre) lies where the ray meets the focus plane.
            let image_point = match self.focus {
                None => p,
                Some(focus) => {
                    let depth = (p - self.pinhole.position).dot(self.pinhole.forward);
                    if depth <= 1e-6 {
                        continue;
                    }
                    l + d * (focus / depth)
                }
            };
            let Some(px) = self
                .pinhole
                .project(image_point)
                .and_then(|uv| self.pinhole.pixel(uv))
            else {
                continue;
            };
            visit(l, px, per_sample * cos_s / (dist2 * cos_a * cos_a * cos_a));
        }
    }
}

/// `n` points spread evenly over the unit disk (Vogel's spiral), deterministic.
pub fn disk_samples(n: usize) -> Vec<(f32, f32)> {
    if n == 1 {
        return vec![(0.0, 0.0)];
    }
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    (0..n)
        .map(|k| {
            let r = ((k as f32 + 0.5) / n as f32).sqrt();
            let a = k as f32 * golden;
            (r * a.cos(), r * a.sin())
        })
        .collect()
}

/// An LED panel.
#[derive(Debug, Clone)]
pub struct Light {
    /// Name in the scene.
    pub name: String,
    /// Sample points on the panel and the area each stands for.
    pub samples: Vec<V3>,
    sample_area: f32,
    /// Emitting direction.
    pub normal: V3,
    /// Colour at the scene's colour temperature, luminance 1.
    pub rgb: LinearRgb,
    /// Radiance scale.
    pub intensity: f64,
}

impl Light {
    /// A panel sampled on a `k × k` grid.
    pub fn new(spec: &LightSpec, k: usize) -> Self {
        let normal = dir(spec.normal);
        let helper = if normal.z.abs() < 0.9 { V3::Z } else { V3::X };
        let e1 = normal.cross(helper).normalize();
        let e2 = normal.cross(e1);
        let (w, h) = (
            (spec.size_mm[0] / 1000.0) as f32,
            (spec.size_mm[1] / 1000.0) as f32,
        );
        let c = mm(spec.center_mm);
        let mut samples = Vec::with_capacity(k * k);
        for j in 0..k {
            for i in 0..k {
                let a = ((i as f32 + 0.5) / k as f32 - 0.5) * w;
                let b = ((j as f32 + 0.5) / k as f32 - 0.5) * h;
                samples.push(c + e1 * a + e2 * b);
            }
        }
        Self {
            name: spec.name.clone(),
            samples,
            sample_area: w * h / (k * k) as f32,
            normal,
            rgb: cct_to_linear_rgb(spec.cct_k),
            intensity: spec.intensity,
        }
    }

    /// Geometric factor to a surface point, ignoring visibility, for each sample:
    /// `cos θ_light cos θ_surface dA / (π d²)` (Lambertian emitter of unit radiance·π).
    pub fn samples_to(&self, p: V3, n: V3, mut visit: impl FnMut(V3, f32)) {
        for &q in &self.samples {
            let d = p - q;
            let dist2 = d.length_squared().max(1e-8);
            let dist = dist2.sqrt();
            let cos_l = self.normal.dot(d) / dist;
            let cos_s = -n.dot(d) / dist;
            if cos_l > 0.0 && cos_s > 0.0 {
                visit(
                    q,
                    cos_l * cos_s * self.sample_area / (std::f32::consts::PI * dist2),
                );
            }
        }
    }
}

/// The equidistant fisheye camera: a ray at angle θ from the axis lands at radius `f θ`.
#[derive(Debug, Clone, Copy)]
pub struct Fisheye {
    /// Centre of projection.
    pub position: V3,
    right: V3,
    down: V3,
    forward: V3,
    focal_px: f32,
    half_fov: f32,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
}

impl Fisheye {
    /// From the scene's camera description: the image circle of `fov_deg` fills the shorter side.
    pub fn new(spec: &CameraSpec) -> Self {
        let position = mm(spec.position_mm);
        let forward = (mm(spec.look_at_mm) - position).normalize();
        let right = forward.cross(dir(spec.up)).normalize();
        let down = forward.cross(right);
        let half_fov = (spec.fov_deg as f32).to_radians() * 0.5;
        let (width, height) = (spec.resolution[0], spec.resolution[1]);
        let focal_px = 0.5 * width.min(height) as f32 / half_fov;
        Self {
            position,
            right,
            down,
            forward,
            focal_px,
            half_fov,
            width,
            height,
        }
    }

    /// The unit ray through image coordinates `(u, v)`, or `None` outside the image circle.
    pub fn ray(&self, u: f32, v: f32) -> Option<V3> {
        let (x, y) = (u - 0.5 * self.width as f32, v - 0.5 * self.height as f32);
        let r = (x * x + y * y).sqrt();
        let theta = r / self.focal_px;
        if theta > self.half_fov {
            return None;
        }
        let (sx, sy) = if r > 0.0 { (x / r, y / r) } else { (0.0, 0.0) };
        Some(
            (self.forward * theta.cos() + (self.right * sx + self.down * sy) * theta.sin())
                .normalize(),
        )
    }

    /// Image coordinates of a world point, or `None` outside the field of view.
    pub fn project(&self, p: V3) -> Option<(f32, f32)> {
        let d = (p - self.position).normalize_or_zero();
        let (x, y, z) = (d.dot(self.right), d.dot(self.down), d.dot(self.forward));
        let theta = z.clamp(-1.0, 1.0).acos();
        if theta > self.half_fov {
            return None;
        }
        let s = (x * x + y * y).sqrt();
        let r = self.focal_px * theta;
        let (ux, uy) = if s > 0.0 { (x / s, y / s) } else { (0.0, 0.0) };
        Some((
            0.5 * self.width as f32 + r * ux,
            0.5 * self.height as f32 + r * uy,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tabulated curve is the power law within 4e-6 of full light for every γ ≥ 1, exact at
    /// black, white and every step, and the power itself below γ = 1.
    #[test]
    fn tabulated_curve_is_the_power_law() {
        for g in [1.0, 1.05, 1.2, 1.5, 2.2, 2.6, 5.0, 0.5] {
            let curve = Curve::new([g; 3]);
            let mut worst = 0.0f64;
            for k in 0..=100_000u32 {
                let code = k as f32 / 100_000.0;
                let want = f64::from(code).powf(g);
                worst = worst.max((f64::from(curve.share(1, code)) - want).abs());
            }
            assert!(worst < 4e-6, "γ {g}: off by {worst:e}");
            assert_eq!(curve.share(0, 0.0).to_bits(), 0f32.to_bits(), "γ {g}");
            assert_eq!(curve.share(0, 1.0).to_bits(), 1f32.to_bits(), "γ {g}");
            assert_eq!(
                curve.share(2, 7.0).to_bits(),
                1f32.to_bits(),
                "γ {g}: clipped"
            );
            let step = 1000.0 / CURVE_STEPS as f32;
            let exact = f64::from(step).powf(g) as f32;
            if g >= 1.0 {
                assert_eq!(curve.share(2, step).to_bits(), exact.to_bits(), "γ {g}");
            }
            assert!(curve.share(0, f32::NAN).is_nan());
        }
    }
}
