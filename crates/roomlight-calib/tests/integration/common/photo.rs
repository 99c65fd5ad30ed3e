//! Photographs of the project's own structured-light patterns as a real camera gives them: a
//! projector lighting a textured, inter-reflecting plane seen in perspective through a lens
//! (Gaussian blur), exposed with read and shot noise, sRGB-encoded and quantised to 8 bits, then
//! decoded back to linear the way `LinearImage::load_png(.., Encoding::Srgb, ..)` does. It owns
//! the ground truth (the projector coordinate of every camera pixel's centre) and the tally of a
//! decode against it; it must not know how the decoder works.

use roomlight_calib::charts::Homography;
use roomlight_calib::graycode::{Correspondence, Manifest};
use roomlight_calib::image_io::LinearImage;

/// What the photographs show and how they are taken.
#[derive(Debug, Clone, Copy)]
pub struct Shot {
    /// Gaussian lens blur, standard deviation in camera pixels.
    pub blur_px: f32,
    /// Linear value of a white pattern on albedo 1 (the exposure); values above 1 clip.
    pub exposure: f32,
    /// Inter-reflected light as a share of the direct light of the pattern's local mean.
    pub interreflection: f32,
    /// Ambient light (room lights) as a share of white.
    pub ambient: f32,
    /// Read noise (standard deviation, linear units) and shot noise at value 1.
    pub noise: (f32, f32),
    /// False: the projector shows nothing (cable out), the photographs see only the room.
    pub projector_on: bool,
    /// Seed of the noise.
    pub seed: u64,
    /// Camera size.
    pub camera: (u32, u32),
}

impl Default for Shot {
    fn default() -> Self {
        Self {
            blur_px: 1.0,
            exposure: 0.8,
            interreflection: 0.25,
            ambient: 0.08,
            noise: (0.003, 0.012),
            projector_on: true,
            seed: 1,
            camera: (320, 240),
        }
    }
}

/// One photographed pattern set and its ground truth.
pub struct Photographs {
    /// One capture per pattern, in the manifest's order.
    pub captures: Vec<LinearImage>,
    /// The projector coordinate seen at each camera pixel's centre where the projector lights
    /// it directly (inside its image, outside the occluder's shadow).
    pub truth: Vec<Option<(f32, f32)>>,
    /// The projector coordinate of every camera pixel's centre on the plane, clamped to the
    /// projector's image (lit or not).
    pub plane: Vec<(f32, f32)>,
}

/// The camera → projector map: a plane seen in perspective, the projector's image filling most
/// of the frame at about 1.2 camera pixels per projector pixel (less on the far side).
fn warp(manifest: &Manifest, camera: (u32, u32)) -> impl Fn(f64, f64) -> (f64, f64) {
    let (pw, ph) = (f64::from(manifest.width), f64::from(manifest.height));
    // Where the camera's corners fall in the projector's image, in projector pixels.
    let corners = [
        [-0.04 * pw, -0.05 * ph],
        [1.03 * pw, -0.09 * ph],
        [1.01 * pw, 1.07 * ph],
        [-0.02 * pw, 1.04 * ph],
    ];
    let h = Homography::from_corners(&corners).expect("a proper quadrilateral");
    let (cw, ch) = (f64::from(camera.0), f64::from(camera.1));
    move |u, v| {
        let [x, y] = h.apply(u * 6.0 / cw, v * 4.0 / ch);
        (x, y)
    }
}

/// Surface albedo at a camera pixel: smooth variation and printed blocks with sharp edges,
/// from 0.2 to 1.0.
fn albedo(u: f64, v: f64) -> f32 {
    let smooth = 0.6 + 0.25 * (u / 23.0).sin() * (v / 31.0).cos() + 0.1 * ((u + v) / 11.0).sin();
    let block = ((u / 37.0).floor() as i64 + 3 * (v / 29.0).floor() as i64).rem_euclid(5);
    let printed = match block {
        0 => 0.45,
        2 => 1.3,
        _ => 1.0,
    };
    (smooth * printed).clamp(0.2, 1.0) as f32
}

/// The occluder's shadow: a disc where the projector does not reach (global light does).
fn shadowed(u: f64, v: f64) -> bool {
    (u - 230.0).powi(2) + (v - 70.0).powi(2) < 22.0f64.powi(2)
}

/// Photographs every pattern of `manifest` under `shot`.
pub fn photograph(manifest: &Manifest, shot: &Shot) -> Photographs {
    let (cw, ch) = (shot.camera.0 as usize, shot.camera.1 as usize);
    let (pw, ph) = (manifest.width as usize, manifest.height as usize);
    let to_projector = warp(manifest, shot.camera);
    let inside = |(x, y): (f64, f64)| x >= 0.0 && y >= 0.0 && x < pw as f64 && y < ph as f64;
    // 3×3 samples per camera pixel: the projector pixel each falls on (None: outside or shadow).
    const SS: usize = 3;
    let mut samples = Vec::with_capacity(cw * ch * SS * SS);
    let mut truth = Vec::with_capacity(cw * ch);
    let mut albedos = Vec::with_capacity(cw * ch);
    let mut centre_at = Vec::with_capacity(cw * ch);
    let mut plane = Vec::with_capacity(cw * ch);
    for v in 0..ch {
        for u in 0..cw {
            let (uc, vc) = (u as f64 + 0.5, v as f64 + 0.5);
            let c = to_projector(uc, vc);
            let lit = inside(c) && !shadowed(uc, vc);
            truth.push(lit.then_some((c.0 as f32, c.1 as f32)));
            albedos.push(albedo(uc, vc));
            let (cx, cy) = (
                c.0.clamp(0.0, pw as f64 - 1.0),
                c.1.clamp(0.0, ph as f64 - 1.0),
            );
            centre_at.push(cy as usize * pw + cx as usize);
            plane.push((cx as f32, cy as f32));
            for sy in 0..SS {
                for sx in 0..SS {
                    let (us, vs) = (
                        u as f64 + (sx as f64 + 0.5) / SS as f64,
                        v as f64 + (sy as f64 + 0.5) / SS as f64,
                    );
                    let p = to_projector(us, vs);
                    samples.push(
                        (inside(p) && !shadowed(us, vs)).then(|| p.1 as usize * pw + p.0 as usize),
                    );
                }
            }
        }
    }
    // The projector's own falloff: dimmer towards its corners.
    let falloff: Vec<f32> = (0..pw * ph)
        .map(|i| {
            let (x, y) = (
                (i % pw) as f32 / pw as f32 - 0.5,
                (i / pw) as f32 / ph as f32 - 0.5,
            );
            1.0 - 0.6 * (x * x + y * y)
        })
        .collect();
    let kernel = gaussian(shot.blur_px);
    let mut rng = Rng(shot.seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1);
    let captures = manifest
        .patterns
        .iter()
        .map(|p| {
            let pattern: Vec<f32> = if shot.projector_on {
                manifest.pattern_values(p.pattern)
            } else {
                vec![0.0; pw * ph]
            };
            let lit: Vec<f32> = pattern.iter().zip(&falloff).map(|(a, b)| a * b).collect();
            let local = box_mean(&lit, pw, ph, 24);
            let radiance: Vec<f32> = (0..cw * ch)
                .map(|i| {
                    let direct = samples[i * SS * SS..(i + 1) * SS * SS]
                        .iter()
                        .map(|s| s.map_or(0.0, |j| lit[j]))
                        .sum::<f32>()
                        / (SS * SS) as f32;
                    // Light from the rest of the room: the pattern's local mean, reflected.
                    let global = if truth[i].is_some() || shadowed_at(i, cw) {
                        shot.interreflection * local[centre_at[i]]
                    } else {
                        0.5 * shot.interreflection * local[centre_at[i]]
                    };
                    shot.exposure * albedos[i] * (direct + global + shot.ambient)
                })
                .collect();
            let blurred = blur(&radiance, cw, ch, &kernel);
            let pixels = blurred
                .iter()
                .map(|&value| {
                    let sigma =
                        (shot.noise.0.powi(2) + shot.noise.1.powi(2) * value.max(0.0)).sqrt();
                    // Each channel's own noise and quantisation.
                    [0; 3].map(|_: u8| {
                        let noisy = (value + sigma * rng.normal()).clamp(0.0, 1.0);
                        srgb_decode((srgb_encode(noisy) * 255.0).round() / 255.0)
                    })
                })
                .collect();
            LinearImage {
                width: shot.camera.0,
                height: shot.camera.1,
                pixels,
            }
        })
        .collect();
    Photographs {
        captures,
        truth,
        plane,
    }
}

/// Whether camera pixel `i` lies in the occluder's shadow.
fn shadowed_at(i: usize, cw: usize) -> bool {
    shadowed((i % cw) as f64 + 0.5, (i / cw) as f64 + 0.5)
}

/// How a decode compares with the truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tally {
    /// Directly lit camera pixels.
    pub lit: usize,
    /// Share of them decoded within ±1 projector pixel (or the tolerance of [`tally_within`]).
    pub close: f64,
    /// Share of them decoded more than 3 projector pixels off.
    pub gross: f64,
    /// Share of them left unknown.
    pub unknown: f64,
    /// Pixels outside the direct light (border, shadow) given a projector pixel.
    pub unlit_decoded: usize,
    /// Of those, how many more than 3 projector pixels from their place on the plane.
    pub unlit_gross: usize,
}

/// Tallies `decoded` against the photographs' truth.
pub fn tally(photos: &Photographs, decoded: &Correspondence) -> Tally {
    tally_within(photos, decoded, 1.0)
}

/// [`tally`] with "close" meaning within `tolerance` projector pixels per axis (the true code
/// cell or the one beside it, for a pattern set over cells: `Manifest::tolerance`) and
/// "gross" more than 2 beyond it (as more than 3 is for ±1).
pub fn tally_within(photos: &Photographs, decoded: &Correspondence, tolerance: f32) -> Tally {
    let off = |(tx, ty): (f32, f32), (x, y): (u32, u32)| {
        (x as f32 - tx.floor())
            .abs()
            .max((y as f32 - ty.floor()).abs())
    };
    let (mut lit, mut close, mut gross, mut unknown) = (0, 0, 0, 0);
    let (mut unlit_decoded, mut unlit_gross) = (0, 0);
    for ((t, p), d) in photos.truth.iter().zip(&photos.plane).zip(&decoded.map) {
        match (t, d) {
            (None, Some(d)) => {
                unlit_decoded += 1;
                unlit_gross += usize::from(off(*p, *d) > tolerance + 2.0);
            }
            (None, None) => {}
            (Some(_), None) => {
                lit += 1;
                unknown += 1;
            }
            (Some(t), Some(d)) => {
                lit += 1;
                let e = off(*t, *d);
                if e <= tolerance {
                    close += 1;
                } else if e > tolerance + 2.0 {
                    gross += 1;
                }
            }
        }
    }
    let share = |n: usize| n as f64 / lit.max(1) as f64;
    Tally {
        lit,
        close: share(close),
        gross: share(gross),
        unknown: share(unknown),
        unlit_decoded,
        unlit_gross,
    }
}

/// A normalised Gaussian kernel of standard deviation `sigma` (a single tap at 0).
fn gaussian(sigma: f32) -> Vec<f32> {
    if sigma <= 0.0 {
        return vec![1.0];
    }
    let r = (3.0 * sigma).ceil() as i32;
    let k: Vec<f32> = (-r..=r)
        .map(|x| (-(x * x) as f32 / (2.0 * sigma * sigma)).exp())
        .collect();
    let sum: f32 = k.iter().sum();
    k.into_iter().map(|v| v / sum).collect()
}

/// Separable convolution with `kernel`, the border clamped.
fn blur(img: &[f32], w: usize, h: usize, kernel: &[f32]) -> Vec<f32> {
    let r = (kernel.len() / 2) as isize;
    let pass = |src: &[f32], horizontal: bool| -> Vec<f32> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as isize, (i / w) as isize);
                kernel
                    .iter()
                    .enumerate()
                    .map(|(k, wt)| {
                        let o = k as isize - r;
                        let j = if horizontal {
                            y as usize * w + (x + o).clamp(0, w as isize - 1) as usize
                        } else {
                            (y + o).clamp(0, h as isize - 1) as usize * w + x as usize
                        };
                        wt * src[j]
                    })
                    .sum()
            })
            .collect()
    };
    pass(&pass(img, true), false)
}

/// The mean of `img` over a `(2r+1)²` box around each pixel (clipped at the border).
fn box_mean(img: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    let mut integral = vec![0.0f64; (w + 1) * (h + 1)];
    for y in 0..h {
        for x in 0..w {
            integral[(y + 1) * (w + 1) + x + 1] = f64::from(img[y * w + x])
                + integral[y * (w + 1) + x + 1]
                + integral[(y + 1) * (w + 1) + x]
                - integral[y * (w + 1) + x];
        }
    }
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let (x0, x1, y0, y1) = (
                x.saturating_sub(r),
                (x + r + 1).min(w),
                y.saturating_sub(r),
                (y + r + 1).min(h),
            );
            let s = integral[y1 * (w + 1) + x1]
                - integral[y0 * (w + 1) + x1]
                - integral[y1 * (w + 1) + x0]
                + integral[y0 * (w + 1) + x0];
            (s / ((x1 - x0) * (y1 - y0)) as f64) as f32
        })
        .collect()
}

fn srgb_encode(v: f32) -> f32 {
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

fn srgb_decode(v: f32) -> f32 {
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// A small deterministic generator (xorshift64*), normal deviates by Box–Muller.
struct Rng(u64);

impl Rng {
    fn uniform(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let bits = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40;
        // In (0, 1]: the logarithm below never sees zero.
        (bits as f32 + 1.0) / (1u64 << 24) as f32
    }

    fn normal(&mut self) -> f32 {
        let (a, b) = (self.uniform(), self.uniform());
        (-2.0 * a.ln()).sqrt() * (std::f32::consts::TAU * b).cos()
    }
}
