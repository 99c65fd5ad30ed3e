//! Radiometry: what makes a camera's frame linear light. 8-bit codes (sRGB, JPEG, video) go
//! through a `Response` (sRGB by default, a gamma, or a measured table); 16-bit values are
//! linear as they are; saturated and under-exposed pixels are flagged in a mask; an optional
//! dark frame is subtracted. `calibrate_response` measures a table from a static scene shot at
//! several exposures (Debevec & Malik 1997, "Recovering high dynamic range radiance maps from
//! photographs", §2.1, hand-written: no maintained crate does it). It must not know backends
//! or charts.

use crate::error::CameraError;
use crate::frame::{Frame, Samples};
use roomlight_calib::image_io::LinearImage;
use serde::{Deserialize, Serialize};

/// How an 8-bit code maps to linear light, 1 at code 255.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Response {
    /// The sRGB transfer function (IEC 61966-2-1), what most webcams and JPEGs use.
    #[default]
    Srgb,
    /// `(code / 255)^gamma`.
    Gamma(f32),
    /// A measured table: the linear value of each of the 256 codes (non-decreasing).
    Table(Vec<f32>),
}

impl Response {
    /// Refuses a gamma that is not finite and positive, and a table that is not 256
    /// non-decreasing finite values ending above zero.
    pub fn validate(&self) -> Result<(), String> {
        match self {
            Self::Srgb => Ok(()),
            Self::Gamma(g) if g.is_finite() && *g > 0.0 => Ok(()),
            Self::Gamma(g) => Err(format!("response gamma {g}; expected finite and positive")),
            Self::Table(t) => {
                if t.len() != 256 {
                    return Err(format!(
                        "response table of {} entries; expected 256",
                        t.len()
                    ));
                }
                if t.iter().any(|v| !v.is_finite()) || t.windows(2).any(|w| w[1] < w[0]) {
                    return Err("response table not finite and non-decreasing".into());
                }
                if t[255] <= 0.0 {
                    return Err("response table ends at zero".into());
                }
                Ok(())
            }
        }
    }

    /// The linear value of every code.
    pub fn table(&self) -> [f32; 256] {
        std::array::from_fn(|z| {
            let c = z as f32 / 255.0;
            match self {
                Self::Srgb => {
                    if c <= 0.04045 {
                        c / 12.92
                    } else {
                        ((c + 0.055) / 1.055).powf(2.4)
                    }
                }
                Self::Gamma(g) => c.powf(*g),
                Self::Table(t) => t.get(z).copied().unwrap_or(f32::NAN),
            }
        })
    }
}

/// A frame made linear, with the pixels the measurement may use.
#[derive(Debug, Clone, PartialEq)]
pub struct Linearized {
    pub image: LinearImage,
    /// Per pixel: true where no channel is saturated or under-exposed.
    pub usable: Vec<bool>,
    /// The linear level at which a channel counts as saturated.
    pub saturation: f32,
}

/// What turns every capture of one camera into linear light.
#[derive(Debug, Clone, PartialEq)]
pub struct Radiometry {
    lut: [f32; 256],
    saturated_code: u8,
    underexposed_code: u8,
    dark: Option<LinearImage>,
}

impl Radiometry {
    /// `saturated_code`/`underexposed_code`: 8-bit thresholds (16-bit values are compared at
    /// the same fraction of full scale). The response must be valid
    /// ([`Response::validate`]).
    pub fn new(response: &Response, saturated_code: u8, underexposed_code: u8) -> Self {
        Self {
            lut: response.table(),
            saturated_code,
            underexposed_code,
            dark: None,
        }
    }

    /// Subtracts `dark` (linear, the camera's own size) from every capture.
    pub fn with_dark_frame(mut self, dark: LinearImage) -> Self {
        self.dark = Some(dark);
        self
    }

    /// The linear level at and above which a channel is saturated.
    pub fn saturation(&self) -> f32 {
        self.lut[usize::from(self.saturated_code)]
    }

    /// The frame in linear light with its mask; `camera` names it in errors.
    pub fn linearize(&self, frame: &Frame, camera: &str) -> Result<Linearized, CameraError> {
        let (pixels, usable): (Vec<[f32; 3]>, Vec<bool>) = match &frame.samples {
            Samples::Rgb8(p) => p
                .iter()
                .map(|c| {
                    let ok = c
                        .iter()
                        .all(|&z| z < self.saturated_code && z > self.underexposed_code);
                    (c.map(|z| self.lut[usize::from(z)]), ok)
                })
                .unzip(),
            Samples::Rgb16(p) => {
                let sat = f32::from(self.saturated_code) / 255.0 * 65535.0;
                let under = f32::from(self.underexposed_code) / 255.0 * 65535.0;
                p.iter()
                    .map(|c| {
                        let v = c.map(f32::from);
                        let ok = v.iter().all(|&x| x < sat && x > under);
                        (v.map(|x| x / 65535.0), ok)
                    })
                    .unzip()
            }
        };
        let mut image = LinearImage {
            width: frame.width,
            height: frame.height,
            pixels,
        };
        let saturation = match &frame.samples {
            Samples::Rgb8(_) => self.saturation(),
            Samples::Rgb16(_) => f32::from(self.saturated_code) / 255.0,
        };
        if let Some(dark) = &self.dark {
            if (dark.width, dark.height) != (image.width, image.height) {
                return Err(CameraError::Radiometry {
                    camera: camera.to_string(),
                    reason: format!(
                        "dark frame of {}×{}, captures of {}×{}",
                        dark.width, dark.height, image.width, image.height
                    ),
                });
            }
            // Not clamped at zero: the noise around black is symmetric, and a clamp would
            // bias dark patches' means upwards.
            for (p, d) in image.pixels.iter_mut().zip(&dark.pixels) {
                for c in 0..3 {
                    p[c] -= d[c];
                }
            }
        }
        Ok(Linearized {
            image,
            usable,
            saturation,
        })
    }
}

/// Debevec–Malik's hat weight: codes near the ends say least about the curve.
fn weight(z: u8) -> f64 {
    f64::from(z.min(255 - z)) + 1.0
}

/// Measures an 8-bit camera's response from frames of one static scene at several exposures
/// (seconds): the least-squares `g(z) = ln E + ln t` with a smoothness term `lambda`
/// (Debevec & Malik eq. 3), all three channels pooled into one curve, over up to `samples`
/// pixels spread over the image. Returns a table normalised to 1 at code 255.
pub fn calibrate_response(
    frames: &[(&Frame, f64)],
    samples: usize,
    lambda: f64,
) -> Result<Response, String> {
    let first = frames.first().ok_or("no frames")?.0;
    if frames.len() < 2 {
        return Err("at least two exposures are needed".into());
    }
    let mut codes = Vec::with_capacity(frames.len());
    for (f, t) in frames {
        if (f.width, f.height) != (first.width, first.height) {
            return Err("frames of different sizes".into());
        }
        if !(t.is_finite() && *t > 0.0) {
            return Err(format!("exposure {t} s; expected finite and positive"));
        }
        match &f.samples {
            Samples::Rgb8(p) => codes.push(p),
            Samples::Rgb16(_) => return Err("16-bit frames are linear already".into()),
        }
    }
    let n_pixels = first.width as usize * first.height as usize;
    let step = (n_pixels / samples.max(1)).max(1);
    // Each sampled pixel's channel is one "pixel" of the paper's formulation.
    let points: Vec<(usize, usize)> = (0..n_pixels)
        .step_by(step)
        .flat_map(|i| (0..3).map(move |c| (i, c)))
        .collect();
    let n = points.len();
    let rows = n * frames.len() + 1 + 254;
    let cols = 256 + n;
    let mut a = nalgebra::DMatrix::<f64>::zeros(rows, cols);
    let mut b = nalgebra::DVector::<f64>::zeros(rows);
    let mut row = 0;
    for (j, (_, t)) in frames.iter().enumerate() {
        for (i, &(p, c)) in points.iter().enumerate() {
            let z = codes[j][p][c];
            let w = weight(z);
            a[(row, usize::from(z))] = w;
            a[(row, 256 + i)] = -w;
            b[row] = w * t.ln();
            row += 1;
        }
    }
    // Fixes the curve's free offset: g(128) = 0.
    a[(row, 128)] = 1.0;
    row += 1;
    for z in 1..255u8 {
        let w = lambda * weight(z);
        let k = usize::from(z);
        a[(row, k - 1)] = w;
        a[(row, k)] = -2.0 * w;
        a[(row, k + 1)] = w;
        row += 1;
    }
    let x = a
        .svd(true, true)
        .solve(&b, 1e-12)
        .map_err(|e| format!("least squares: {e}"))?;
    let top = x[255];
    let mut table: Vec<f32> = (0..256).map(|z| (x[z] - top).exp() as f32).collect();
    // The curve is monotone by physics; noise at the ends must not make it otherwise.
    for z in 1..256 {
        table[z] = table[z].max(table[z - 1]);
    }
    let response = Response::Table(table);
    response.validate()?;
    Ok(response)
}
