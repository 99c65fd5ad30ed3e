//! Chart sampling (DESIGN §4.3): the chart's four corners in the camera image → a homography →
//! a sample box in the inner half of each patch → a trimmed mean with its standard error (the
//! patch's noise) and a saturation flag.

use crate::CalibError;
use crate::image_io::LinearImage;
use nalgebra::{DMatrix, Matrix3, Vector3};
use roomlight_core::LinearRgb;
use serde::{Deserialize, Serialize};

/// Patch columns and rows of the 24-patch chart.
pub const COLUMNS: usize = 6;
/// Rows of the chart.
pub const ROWS: usize = 4;
/// Side of a patch square as a share of the patch pitch (the rest is the black frame).
pub const PATCH_SIDE: f64 = 0.8;

/// Where a chart is in the camera image: its outer corners, top-left, top-right, bottom-right,
/// bottom-left (top is the row of patches 1–6), in pixel coordinates (pixel centres at +0.5).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChartCorners {
    /// The chart's name in the room config.
    pub name: String,
    /// Four corners in camera pixels.
    pub corners: [[f64; 2]; 4],
}

/// Why a patch was left out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PatchStatus {
    /// Measured.
    Ok,
    /// Some pixel of the sample box reached saturation: the mean would be biased.
    Saturated,
    /// The sample box leaves the image.
    OutOfImage,
    /// Fewer than four pixels in the sample box.
    TooFewPixels,
    /// The two halves of the sample box differ by more than noise allows: an edge (a shadow, a
    /// frustum or node boundary) crosses the patch, so its mean depends on where one samples.
    NonUniform,
}

/// How to sample patches.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SampleConfig {
    /// Values at or above this are saturated.
    pub saturation: f32,
    /// The camera's noise at black (standard deviation of one pixel).
    pub read_noise: f32,
    /// The camera's shot noise at value 1 (it grows with √value).
    pub shot_noise: f32,
    /// Largest difference between the halves of a sample box, as a share of the mean, beyond
    /// the noise, before the patch is called non-uniform.
    pub max_nonuniformity: f64,
}

impl Default for SampleConfig {
    fn default() -> Self {
        Self {
            saturation: 0.98,
            read_noise: 0.001,
            shot_noise: 0.004,
            max_nonuniformity: 0.03,
        }
    }
}

/// One patch's measurement.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PatchSample {
    /// Trimmed mean (linear camera values); zero unless the status is `Ok` or `NonUniform`.
    pub mean: LinearRgb,
    /// Standard error of the mean per channel: the patch's noise `σ`.
    pub std_error: LinearRgb,
    /// Pixels averaged (after trimming).
    pub pixels: usize,
    /// Measured, or why not.
    pub status: PatchStatus,
}

/// The map from chart coordinates (u across 0..6, v down 0..4, in patch pitches) to camera pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Homography(Matrix3<f64>);

impl Homography {
    /// From the four corners (DLT, exact for four points).
    pub fn from_corners(corners: &[[f64; 2]; 4]) -> Option<Self> {
        let src = [
            [0.0, 0.0],
            [COLUMNS as f64, 0.0],
            [COLUMNS as f64, ROWS as f64],
            [0.0, ROWS as f64],
        ];
        let mut a = DMatrix::<f64>::zeros(8, 9);
        for k in 0..4 {
            let ([x, y], [u, v]) = (src[k], corners[k]);
            a.row_mut(2 * k)
                .copy_from_slice(&[x, y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y, -u]);
            a.row_mut(2 * k + 1)
                .copy_from_slice(&[0.0, 0.0, 0.0, x, y, 1.0, -v * x, -v * y, -v]);
        }
        // The null vector of A: the right singular vector of the smallest singular value.
        let svd = a.transpose() * &a;
        let eig = svd.symmetric_eigen();
        let (k, _) = eig
            .eigenvalues
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))?;
        let h = eig.eigenvectors.column(k);
        let m = Matrix3::from_row_slice(h.as_slice());
        if !m.iter().all(|v| v.is_finite()) || m.determinant().abs() < 1e-300 {
            return None;
        }
        Some(Self(m))
    }

    /// Camera pixel of a chart point.
    pub fn apply(&self, u: f64, v: f64) -> [f64; 2] {
        let p = self.0 * Vector3::new(u, v, 1.0);
        // A point at infinity cannot come from a chart in front of the camera; report it far away.
        if p.z.abs() < 1e-300 {
            return [f64::INFINITY, f64::INFINITY];
        }
        [p.x / p.z, p.y / p.z]
    }
}

/// Whether `p` lies inside the convex quadrilateral `q` (either winding).
fn inside(q: &[[f64; 2]; 4], p: [f64; 2]) -> bool {
    let (mut positive, mut negative) = (false, false);
    for k in 0..4 {
        let (a, b) = (q[k], q[(k + 1) % 4]);
        let cross = (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
        positive |= cross > 1e-12;
        negative |= cross < -1e-12;
    }
    !(positive && negative)
}

/// [`trimmed`], its standard error never below the camera's noise model for this many pixels
/// (with a handful of pixels the sample spread is itself noisy).
fn trimmed_with_floor(
    values: &mut [[f32; 3]],
    config: &SampleConfig,
) -> (LinearRgb, LinearRgb, usize) {
    let (mean, sample_se, pixels) = trimmed(values);
    let std_error = LinearRgb(std::array::from_fn(|c| {
        let model = ((f64::from(config.read_noise).powi(2)
            + f64::from(config.shot_noise).powi(2) * mean[c].max(0.0))
            / pixels.max(1) as f64)
            .sqrt();
        sample_se[c].max(model)
    }));
    (mean, std_error, pixels)
}

/// Per-channel trimmed mean (the top and bottom 10% dropped) and its standard error.
fn trimmed(values: &mut [[f32; 3]]) -> (LinearRgb, LinearRgb, usize) {
    let n = values.len();
    let cut = n / 10;
    let mut mean = LinearRgb::ZERO;
    let mut se = LinearRgb::ZERO;
    let kept = n - 2 * cut;
    for c in 0..3 {
        let mut ch: Vec<f64> = values.iter().map(|v| f64::from(v[c])).collect();
        ch.sort_by(f64::total_cmp);
        let part = &ch[cut..n - cut];
        let m = part.iter().sum::<f64>() / kept as f64;
        // One pixel: no spread to estimate; the standard error is unknown and reported as 0.
        let var = if kept > 1 {
            part.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (kept - 1) as f64
        } else {
            0.0
        };
        mean[c] = m;
        se[c] = (var / kept as f64).sqrt();
    }
    (mean, se, kept)
}

/// Samples the 24 patches of a chart in a capture. Corners outside the image are an error; a
/// patch whose box leaves the image or touches `saturation` is reported and left out.
pub fn sample_chart(
    image: &LinearImage,
    chart: &ChartCorners,
    config: &SampleConfig,
) -> Result<Vec<PatchSample>, CalibError> {
    let hom = chart_homography(image, chart)?;
    Ok((0..COLUMNS * ROWS)
        .map(|k| sample_patch(image, &hom, k, config))
        .collect())
}

/// The chart's homography from patch units to image pixels, once its corners are known to lie
/// in the image and to form a convex quadrilateral of at least 16 pixels.
fn chart_homography(image: &LinearImage, chart: &ChartCorners) -> Result<Homography, CalibError> {
    let (w, h) = (f64::from(image.width), f64::from(image.height));
    for c in &chart.corners {
        if !(c[0].is_finite()
            && c[1].is_finite()
            && c[0] >= 0.0
            && c[1] >= 0.0
            && c[0] <= w
            && c[1] <= h)
        {
            return Err(CalibError::Invalid {
                field: "chart corners",
                problem: format!(
                    "chart {}: corner {c:?} is outside the {}x{} image",
                    chart.name, image.width, image.height
                ),
            });
        }
    }
    let q = &chart.corners;
    let crosses: Vec<f64> = (0..4)
        .map(|k| {
            let (a, b, c) = (q[k], q[(k + 1) % 4], q[(k + 2) % 4]);
            (b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0])
        })
        .collect();
    let area = 0.5
        * (0..4)
            .map(|k| q[k][0] * q[(k + 1) % 4][1] - q[(k + 1) % 4][0] * q[k][1])
            .sum::<f64>()
            .abs();
    let convex = crosses.iter().all(|&c| c > 0.0) || crosses.iter().all(|&c| c < 0.0);
    if !convex || area < 16.0 {
        return Err(CalibError::Invalid {
            field: "chart corners",
            problem: format!(
                "chart {}: the corners {:?} do not form a convex quadrilateral of at least 16 pixels",
                chart.name, chart.corners
            ),
        });
    }
    Homography::from_corners(&chart.corners).ok_or_else(|| CalibError::Invalid {
        field: "chart corners",
        problem: format!(
            "chart {}: the corners {:?} do not form a quadrilateral",
            chart.name, chart.corners
        ),
    })
}

/// Patch `k` (row-major, six columns): the trimmed mean of the pixels inside the inner half of
/// its square, or why it cannot be used.
fn sample_patch(
    image: &LinearImage,
    hom: &Homography,
    k: usize,
    config: &SampleConfig,
) -> PatchSample {
    let (w, h) = (f64::from(image.width), f64::from(image.height));
    let (col, row) = ((k % COLUMNS) as f64, (k / COLUMNS) as f64);
    let half = 0.25 * PATCH_SIDE; // the inner half of the patch square
    let (cu, cv) = (col + 0.5, row + 0.5);
    let quad = [
        hom.apply(cu - half, cv - half),
        hom.apply(cu + half, cv - half),
        hom.apply(cu + half, cv + half),
        hom.apply(cu - half, cv + half),
    ];
    let out_of_image = quad
        .iter()
        .any(|p| !(p[0] >= 0.0 && p[1] >= 0.0 && p[0] <= w && p[1] <= h));
    if out_of_image {
        return PatchSample {
            mean: LinearRgb::ZERO,
            std_error: LinearRgb::ZERO,
            pixels: 0,
            status: PatchStatus::OutOfImage,
        };
    }
    let PatchPixels {
        mut values,
        side,
        saturated,
    } = pixels_in(image, hom, &quad, (cu, cv), config.saturation);
    let status = if saturated {
        PatchStatus::Saturated
    } else if values.len() < 4 {
        PatchStatus::TooFewPixels
    } else if nonuniform(&values, &side, config) {
        PatchStatus::NonUniform
    } else {
        PatchStatus::Ok
    };
    // A non-uniform patch keeps its mean: the box is the same in every capture, so the mean is
    // still what this patch measures; whether one capture's flag is an edge or noise is for the
    // caller to judge across captures (see `attenuation::solve`).
    if matches!(status, PatchStatus::Ok | PatchStatus::NonUniform) {
        let (mean, std_error, pixels) = trimmed_with_floor(&mut values, config);
        PatchSample {
            mean,
            std_error,
            pixels,
            status,
        }
    } else {
        PatchSample {
            mean: LinearRgb::ZERO,
            std_error: LinearRgb::ZERO,
            pixels: values.len(),
            status,
        }
    }
}

/// The pixels of a patch's box.
struct PatchPixels {
    values: Vec<[f32; 3]>,
    /// Per pixel, which side of the patch centre it lies on along the chart's u and v axes.
    side: Vec<(bool, bool)>,
    /// Any pixel at the saturation level or not finite.
    saturated: bool,
}

/// The pixels whose centres lie inside `quad` (the patch's inner half around patch coordinates
/// `(cu, cv)`, inside the image).
fn pixels_in(
    image: &LinearImage,
    hom: &Homography,
    quad: &[[f64; 2]; 4],
    (cu, cv): (f64, f64),
    saturation: f32,
) -> PatchPixels {
    let (x0, x1) = (
        quad.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min),
        quad.iter().map(|p| p[0]).fold(0.0, f64::max),
    );
    let (y0, y1) = (
        quad.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min),
        quad.iter().map(|p| p[1]).fold(0.0, f64::max),
    );
    let mut values = Vec::new();
    let mut side = Vec::new();
    let mut saturated = false;
    let centre = hom.apply(cu, cv);
    let (axis_u, axis_v) = (hom.apply(cu + 1.0, cv), hom.apply(cu, cv + 1.0));
    let (du, dv) = (
        [axis_u[0] - centre[0], axis_u[1] - centre[1]],
        [axis_v[0] - centre[0], axis_v[1] - centre[1]],
    );
    for y in (y0.floor() as u32)..(y1.ceil() as u32).min(image.height) {
        for x in (x0.floor() as u32)..(x1.ceil() as u32).min(image.width) {
            if inside(quad, [f64::from(x) + 0.5, f64::from(y) + 0.5]) {
                let v = image.pixels[(y * image.width + x) as usize];
                saturated |= v.iter().any(|&c| c >= saturation || !c.is_finite());
                values.push(v);
                let (px, py) = (
                    f64::from(x) + 0.5 - centre[0],
                    f64::from(y) + 0.5 - centre[1],
                );
                side.push((
                    px * du[0] + py * du[1] >= 0.0,
                    px * dv[0] + py * dv[1] >= 0.0,
                ));
            }
        }
    }
    PatchPixels {
        values,
        side,
        saturated,
    }
}

/// True when the two halves of the box (along the chart's u or v axis) differ by more than
/// `max_nonuniformity` of the mean plus four standard deviations of the noise.
fn nonuniform(values: &[[f32; 3]], side: &[(bool, bool)], config: &SampleConfig) -> bool {
    let var = |m: f64, n: usize| {
        (f64::from(config.read_noise).powi(2) + f64::from(config.shot_noise).powi(2) * m.max(0.0))
            / n as f64
    };
    // The spread of the box against the camera's noise: an edge inside the box shows as a
    // spread far above noise (a χ² test with 3σ), beyond what a smooth gradient gives.
    let n = values.len();
    for c in 0..3 {
        let m = values.iter().map(|v| f64::from(v[c])).sum::<f64>() / n as f64;
        let sd = (values
            .iter()
            .map(|v| (f64::from(v[c]) - m).powi(2))
            .sum::<f64>()
            / (n - 1).max(1) as f64)
            .sqrt();
        if sd > (3.0 * var(m, 1).sqrt()).max(config.max_nonuniformity * m) {
            return true;
        }
    }
    for split in [0, 1] {
        let mut sums = [[0.0f64; 3]; 2];
        let mut counts = [0usize; 2];
        for (v, s) in values.iter().zip(side) {
            let k = usize::from(if split == 0 { s.0 } else { s.1 });
            counts[k] += 1;
            for c in 0..3 {
                sums[k][c] += f64::from(v[c]);
            }
        }
        if counts[0] == 0 || counts[1] == 0 {
            continue;
        }
        for (sa, sb) in sums[0].iter().zip(&sums[1]) {
            let (a, b) = (sa / counts[0] as f64, sb / counts[1] as f64);
            let noise = (var(a, counts[0]) + var(b, counts[1])).sqrt();
            if (a - b).abs() > config.max_nonuniformity * 0.5 * (a + b) + 4.0 * noise {
                return true;
            }
        }
    }
    false
}

/// Samples every chart; patches are numbered chart-major (chart `m`, patch `k` → `24 m + k`).
/// Samples a region given by its camera pixels (row-major indices), e.g. a patch of the
/// projection-mapping target: the trimmed mean and its standard error as for a chart patch
/// (never below the camera's noise model), saturated if any pixel reaches `saturation`.
pub fn sample_region(image: &LinearImage, pixels: &[u32], config: &SampleConfig) -> PatchSample {
    let empty = |status| PatchSample {
        mean: LinearRgb::ZERO,
        std_error: LinearRgb::ZERO,
        pixels: 0,
        status,
    };
    let mut values = Vec::with_capacity(pixels.len());
    for &i in pixels {
        match image.pixels.get(i as usize) {
            Some(v) => values.push(*v),
            None => return empty(PatchStatus::OutOfImage),
        }
    }
    if values.iter().flatten().any(|v| *v >= config.saturation) {
        return empty(PatchStatus::Saturated);
    }
    if values.len() < 4 {
        return empty(PatchStatus::TooFewPixels);
    }
    let (mean, std_error, pixels) = trimmed_with_floor(&mut values, config);
    PatchSample {
        mean,
        std_error,
        pixels,
        status: PatchStatus::Ok,
    }
}

pub fn sample_charts(
    image: &LinearImage,
    charts: &[ChartCorners],
    config: &SampleConfig,
) -> Result<Vec<PatchSample>, CalibError> {
    let mut all = Vec::with_capacity(charts.len() * 24);
    for chart in charts {
        all.extend(sample_chart(image, chart, config)?);
    }
    Ok(all)
}
