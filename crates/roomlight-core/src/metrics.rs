//! What we measure (DESIGN §3.5, §5, §9): the objective `G`, CIEDE2000 on the patches, and the
//! RMS and ANSI contrast of projection mapping.

use crate::rgb::LinearRgb;
use palette::color_difference::Ciede2000;
use palette::{FromColor, Lab, LinSrgb, white_point::D65};

/// What was wrong with a metric's input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MetricError {
    /// Nothing to measure.
    #[error("{what}: no samples")]
    Empty { what: &'static str },
    /// The lists to compare differ in length.
    #[error("{what}: {got} values against {expected}")]
    Length {
        what: &'static str,
        got: usize,
        expected: usize,
    },
    /// A sample is NaN or infinite.
    #[error("{what}: sample {index} is {value}, expected a finite number")]
    NotFinite {
        what: &'static str,
        index: usize,
        value: f64,
    },
    /// The denominator of a ratio is zero or negative, so the ratio has no meaning.
    #[error("{what}: the {denominator} is {value}, expected a value > 0")]
    NonPositive {
        what: &'static str,
        denominator: &'static str,
        value: f64,
    },
    /// A region reaches outside the image.
    #[error("{what}: region {region:?} reaches outside the {width}x{height} image")]
    OutOfImage {
        what: &'static str,
        region: Rect,
        width: usize,
        height: usize,
    },
}

/// `G = ½ Σ_i ‖e_i‖²` over patches and channels (DESIGN §2).
pub fn objective(errors: &[LinearRgb]) -> f64 {
    0.5 * errors.iter().map(|e| e.norm_squared()).sum::<f64>()
}

/// Relative luminance of a linear RGB value with sRGB (Rec. 709) primaries.
pub fn luminance(rgb: LinearRgb) -> f64 {
    0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
}

/// CIELAB (D65) of a linear camera RGB value taken as linear sRGB, scaled so that luminance
/// `white_luminance` is L* = 100. `white_luminance ≤ 0` is treated as 1 (no scaling).
pub fn lab_from_linear_rgb(rgb: LinearRgb, white_luminance: f64) -> [f64; 3] {
    let w = if white_luminance > 0.0 {
        white_luminance
    } else {
        1.0
    };
    let lab: Lab<D65, f64> = Lab::from_color(LinSrgb::new(rgb[0] / w, rgb[1] / w, rgb[2] / w));
    [lab.l, lab.a, lab.b]
}

/// CIEDE2000 between two CIELAB colours (Sharma, Wu & Dalal 2005), via `palette`.
pub fn ciede2000(lab1: [f64; 3], lab2: [f64; 3]) -> f64 {
    let a: Lab<D65, f64> = Lab::new(lab1[0], lab1[1], lab1[2]);
    let b: Lab<D65, f64> = Lab::new(lab2[0], lab2[1], lab2[2]);
    a.difference(b)
}

/// CIEDE2000 per patch with its mean and max.
#[derive(Debug, Clone, PartialEq)]
pub struct PatchDeltaE {
    /// ΔE00 of each patch.
    pub per_patch: Vec<f64>,
    /// Mean over the patches.
    pub mean: f64,
    /// Largest patch value.
    pub max: f64,
}

/// ΔE00 between target and achieved patch colours, both linear camera RGB, with the brightest
/// target patch as the white (L* = 100).
pub fn patch_delta_e(
    target: &[LinearRgb],
    achieved: &[LinearRgb],
) -> Result<PatchDeltaE, MetricError> {
    const WHAT: &str = "patch ΔE00";
    if target.is_empty() {
        return Err(MetricError::Empty { what: WHAT });
    }
    if achieved.len() != target.len() {
        return Err(MetricError::Length {
            what: WHAT,
            got: achieved.len(),
            expected: target.len(),
        });
    }
    for (index, v) in target.iter().chain(achieved).enumerate() {
        if !v.is_finite() {
            return Err(MetricError::NotFinite {
                what: WHAT,
                index: index % target.len(),
                value: v.0.into_iter().find(|x| !x.is_finite()).unwrap_or(f64::NAN),
            });
        }
    }
    let white = target.iter().map(|&t| luminance(t)).fold(0.0, f64::max);
    let per_patch: Vec<f64> = target
        .iter()
        .zip(achieved)
        .map(|(&t, &a)| {
            ciede2000(
                lab_from_linear_rgb(t.map(|v| v.max(0.0)), white),
                lab_from_linear_rgb(a.map(|v| v.max(0.0)), white),
            )
        })
        .collect();
    let mean = per_patch.iter().sum::<f64>() / per_patch.len() as f64;
    let max = per_patch.iter().copied().fold(0.0, f64::max);
    Ok(PatchDeltaE {
        per_patch,
        mean,
        max,
    })
}

/// RMS contrast of a region: the standard deviation of its luminance over its mean (Peli's
/// definition, independent of exposure; ambient light raises the mean and lowers it).
pub fn rms_contrast(luminance: &[f64]) -> Result<f64, MetricError> {
    const WHAT: &str = "RMS contrast";
    if luminance.is_empty() {
        return Err(MetricError::Empty { what: WHAT });
    }
    if let Some((index, &value)) = luminance.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(MetricError::NotFinite {
            what: WHAT,
            index,
            value,
        });
    }
    let n = luminance.len() as f64;
    let mean = luminance.iter().sum::<f64>() / n;
    if mean <= 0.0 {
        return Err(MetricError::NonPositive {
            what: WHAT,
            denominator: "mean luminance",
            value: mean,
        });
    }
    let var = luminance.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    Ok(var.sqrt() / mean)
}

/// An axis-aligned rectangle in image pixels (`x`, `y` of the top-left corner).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rect {
    /// Left edge.
    pub x: f64,
    /// Top edge.
    pub y: f64,
    /// Width.
    pub width: f64,
    /// Height.
    pub height: f64,
}

/// A single-channel image, row-major.
#[derive(Debug, Clone, Copy)]
pub struct GrayImage<'a> {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width · height` samples, row by row.
    pub pixels: &'a [f32],
}

/// The ANSI contrast of a 4×4 checkerboard and its two means.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnsiContrast {
    /// Mean of the white squares over mean of the black squares.
    pub ratio: f64,
    /// Mean of the white squares.
    pub white_mean: f64,
    /// Mean of the black squares.
    pub black_mean: f64,
}

/// ANSI contrast (DESIGN §5): a 4×4 checker occupies `board`; squares alternate starting with
/// white at the top left if `top_left_white`. Each square is sampled in its central half (pixel
/// centres inside) so that blur at the edges does not count.
pub fn ansi_contrast(
    image: GrayImage<'_>,
    board: Rect,
    top_left_white: bool,
) -> Result<AnsiContrast, MetricError> {
    const WHAT: &str = "ANSI contrast";
    if image.pixels.len() != image.width * image.height {
        return Err(MetricError::Length {
            what: WHAT,
            got: image.pixels.len(),
            expected: image.width * image.height,
        });
    }
    let inside = board.x >= 0.0
        && board.y >= 0.0
        && board.width > 0.0
        && board.height > 0.0
        && board.x + board.width <= image.width as f64
        && board.y + board.height <= image.height as f64;
    if !inside {
        return Err(MetricError::OutOfImage {
            what: WHAT,
            region: board,
            width: image.width,
            height: image.height,
        });
    }
    let (sw, sh) = (board.width / 4.0, board.height / 4.0);
    let mut sums = [(0.0f64, 0usize); 2]; // [black, white]
    for row in 0..4 {
        for col in 0..4 {
            let white = ((row + col) % 2 == 0) == top_left_white;
            let x0 = board.x + (col as f64 + 0.25) * sw;
            let y0 = board.y + (row as f64 + 0.25) * sh;
            let (x1, y1) = (x0 + 0.5 * sw, y0 + 0.5 * sh);
            for py in (y0.floor() as usize)..(y1.ceil() as usize).min(image.height) {
                let cy = py as f64 + 0.5;
                if cy < y0 || cy > y1 {
                    continue;
                }
                for px in (x0.floor() as usize)..(x1.ceil() as usize).min(image.width) {
                    let cx = px as f64 + 0.5;
                    if cx < x0 || cx > x1 {
                        continue;
                    }
                    let v = f64::from(image.pixels[py * image.width + px]);
                    if !v.is_finite() {
                        return Err(MetricError::NotFinite {
                            what: WHAT,
                            index: py * image.width + px,
                            value: v,
                        });
                    }
                    let slot = &mut sums[usize::from(white)];
                    slot.0 += v;
                    slot.1 += 1;
                }
            }
        }
    }
    if sums[0].1 == 0 || sums[1].1 == 0 {
        return Err(MetricError::Empty { what: WHAT });
    }
    let black_mean = sums[0].0 / sums[0].1 as f64;
    let white_mean = sums[1].0 / sums[1].1 as f64;
    if black_mean <= 0.0 {
        return Err(MetricError::NonPositive {
            what: WHAT,
            denominator: "mean of the black squares",
            value: black_mean,
        });
    }
    Ok(AnsiContrast {
        ratio: white_mean / black_mean,
        white_mean,
        black_mean,
    })
}
