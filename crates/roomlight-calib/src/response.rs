//! Projector response (DESIGN §2): a gray ramp on a white patch, fitted per channel with a power
//! law and inverted, so that node values are linear light.

use crate::CalibError;
use crate::graycode::Correspondence;
use crate::image_io::LinearImage;
use roomlight_core::LinearRgb;
use serde::{Deserialize, Serialize};

/// Fewest ramp levels accepted: the ends and two levels between, which fit the one exponent
/// per channel and check it (the ramp is read as a mean over thousands of camera pixels, so
/// each level's own noise is far below the fit's 2% floor).
pub const MIN_LEVELS: usize = 4;

/// The codes of a ramp of `levels` steps from 0 to 1.
pub fn ramp_codes(levels: usize) -> Result<Vec<f64>, CalibError> {
    if levels < MIN_LEVELS {
        return Err(CalibError::Invalid {
            field: "ramp levels",
            problem: format!("{levels}, expected at least {MIN_LEVELS}"),
        });
    }
    Ok((0..levels)
        .map(|j| j as f64 / (levels - 1) as f64)
        .collect())
}

/// A projector's measured response: light share `= code^γ` per channel, black removed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Response {
    /// Exponent per channel.
    pub gamma: [f64; 3],
    /// Largest deviation of a measured level from the fitted curve (share of full range).
    pub max_residual: [f64; 3],
}

impl Response {
    /// A linear projector (already linearised).
    pub fn linear() -> Self {
        Self {
            gamma: [1.0; 3],
            max_residual: [0.0; 3],
        }
    }

    /// The code that gives linear light `share` (clipped to `[0, 1]`) on each channel.
    ///
    /// Computed in single precision, which is what a code is kept in: within 3e-7 of the
    /// double-precision power (far below any projector's 8 to 12 bits), at less than half its
    /// cost (three powers a pixel are most of drawing a frame).
    #[inline]
    pub fn to_code(&self, share: LinearRgb) -> [f32; 3] {
        std::array::from_fn(|c| {
            (share[c].clamp(0.0, 1.0) as f32).powf((1.0 / self.gamma[c]) as f32)
        })
    }

    /// [`Self::to_code`], reusing `last`'s code when `share` is bit for bit its light (a node's
    /// flat inside, everything outside the nodes: three powers a pixel are most of drawing a
    /// frame otherwise); `last` becomes this light and its code.
    #[inline]
    pub fn to_code_after(
        &self,
        share: LinearRgb,
        last: &mut Option<(LinearRgb, [f32; 3])>,
    ) -> [f32; 3] {
        match *last {
            Some((seen, code)) if seen.0.map(f64::to_bits) == share.0.map(f64::to_bits) => code,
            _ => {
                let code = self.to_code(share);
                *last = Some((share, code));
                code
            }
        }
    }

    /// [`Self::to_code`] by table, for drawing whole frames: see [`Encoder`].
    pub fn encoder(&self) -> Encoder {
        Encoder::new(self)
    }

    /// The light share of a code.
    pub fn to_share(&self, code: [f32; 3]) -> LinearRgb {
        LinearRgb(std::array::from_fn(|c| {
            f64::from(code[c]).clamp(0.0, 1.0).powf(self.gamma[c])
        }))
    }
}

/// Fits the response from a ramp: `measured[j]` is the patch value (with its standard error
/// `noise[j]`) at `codes[j]`; `codes` start at 0 and end at 1.
///
/// Each channel is normalised to `(y − y₀)/(y_max − y₀)` and `log share = γ log code` is fitted
/// by least squares over the levels whose share stands clear of the noise (share > 2%).
pub fn fit_response(
    codes: &[f64],
    measured: &[LinearRgb],
    noise: &[LinearRgb],
) -> Result<Response, CalibError> {
    if codes.len() != measured.len() || codes.len() != noise.len() {
        return Err(CalibError::Invalid {
            field: "ramp",
            problem: format!(
                "{} codes, {} measurements, {} noise values",
                codes.len(),
                measured.len(),
                noise.len()
            ),
        });
    }
    if codes.len() < MIN_LEVELS
        || codes.first() != Some(&0.0)
        || codes.last() != Some(&1.0)
        || codes.windows(2).any(|w| w[1] <= w[0])
    {
        return Err(CalibError::Invalid {
            field: "ramp codes",
            problem: format!("expected at least {MIN_LEVELS} increasing codes from 0 to 1"),
        });
    }
    let last = codes.len() - 1;
    let mut gamma = [0.0; 3];
    let mut max_residual = [0.0; 3];
    for c in 0..3 {
        let range = measured[last][c] - measured[0][c];
        let sigma = (noise[last][c].powi(2) + noise[0][c].powi(2)).sqrt();
        if !(range > 10.0 * sigma && range > 0.0) {
            return Err(CalibError::Invalid {
                field: "ramp",
                problem: format!(
                    "channel {c}: white − black is {range:.3e} against noise {sigma:.3e}; the patch is not lit by this projector"
                ),
            });
        }
        let (mut sxx, mut sxy) = (0.0, 0.0);
        let mut used = 0;
        for j in 1..last {
            let share = (measured[j][c] - measured[0][c]) / range;
            if share > 0.02 && codes[j] > 0.0 {
                let (x, y) = (codes[j].ln(), share.ln());
                sxx += x * x;
                sxy += x * y;
                used += 1;
            }
        }
        if used < 2 || sxx <= 0.0 {
            return Err(CalibError::Invalid {
                field: "ramp",
                problem: format!(
                    "channel {c}: only {used} levels above the noise, expected at least 2"
                ),
            });
        }
        gamma[c] = sxy / sxx;
        if !(gamma[c].is_finite() && (0.2..=5.0).contains(&gamma[c])) {
            return Err(CalibError::Invalid {
                field: "ramp",
                problem: format!(
                    "channel {c}: fitted gamma {:.3} is not a projector response",
                    gamma[c]
                ),
            });
        }
        max_residual[c] = (0..=last)
            .map(|j| ((measured[j][c] - measured[0][c]) / range - codes[j].powf(gamma[c])).abs())
            .fold(0.0, f64::max);
    }
    Ok(Response {
        gamma,
        max_residual,
    })
}

/// The mean camera value over the pixels a projector was decoded on, at each ramp level, with
/// its standard error; pixels saturated at full white are left out.
pub fn footprint_ramp(
    ramp: &[&LinearImage],
    corr: &Correspondence,
) -> (Vec<LinearRgb>, Vec<LinearRgb>) {
    let top = ramp.last();
    let pixels: Vec<usize> = corr
        .map
        .iter()
        .enumerate()
        .filter(|(i, m)| {
            m.is_some()
                && top.is_some_and(|t| {
                    t.pixels
                        .get(*i)
                        .is_some_and(|p| p.iter().all(|&v| v < 0.98))
                })
        })
        .map(|(i, _)| i)
        .collect();
    // No pixel: zeros, which the fit refuses with a message naming the projector.
    let count = pixels.len().max(1) as f64;
    ramp.iter()
        .map(|img| {
            let mut sum = LinearRgb::ZERO;
            let mut sq = LinearRgb::ZERO;
            for &i in &pixels {
                let v = LinearRgb(img.pixels[i].map(f64::from));
                sum += v;
                sq += v.hadamard(v);
            }
            let mean = sum * (1.0 / count);
            let var = (sq * (1.0 / count) - mean.hadamard(mean)).map(|v| v.max(0.0));
            (mean, var.map(|v| (v / count).sqrt()))
        })
        .unzip()
}

/// Octaves of light below full the [`Encoder`]'s table covers (down to 2⁻²⁴ ≈ 6e-8 of full
/// light); darker light takes the power itself.
const ENCODER_OCTAVES: u32 = 24;

/// Table steps per octave of light (the top 8 bits of an `f32`'s mantissa).
const ENCODER_STEPS: u32 = 256;

/// A response's `code = share^(1/γ)` as a table, for drawing frames: indexed by the light's
/// `f32` exponent and the top 8 bits of its mantissa, so the steps are 1/256 of the light
/// wherever it is (the curve is steep near black, where a uniform table would fail), and read
/// with linear interpolation in between. Within 1e-6 of [`Response::to_code`] for γ from 1 to
/// 4 (tested), exact at 0 and 1; light under 2⁻²⁴ of full and NaN take the power itself. A
/// power per channel and pixel was most of drawing a frame. Hand-written: no crate tabulates a
/// power this way.
#[derive(Clone)]
pub struct Encoder {
    exponent: [f32; 3],
    tables: [Vec<f32>; 3],
}

impl std::fmt::Debug for Encoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Encoder(1/γ {:?})", self.exponent)
    }
}

impl Encoder {
    fn new(response: &Response) -> Self {
        let exponent = response.gamma.map(|g| (1.0 / g) as f32);
        let len = (ENCODER_OCTAVES * ENCODER_STEPS + 1) as usize;
        let tables = response.gamma.map(|g| {
            (0..len)
                .map(|k| {
                    let (octave, step) = (k as u32 / ENCODER_STEPS, k as u32 % ENCODER_STEPS);
                    let light = (1.0 + f64::from(step) / f64::from(ENCODER_STEPS))
                        * 2f64.powi(octave as i32 - ENCODER_OCTAVES as i32);
                    light.powf(1.0 / g) as f32
                })
                .collect()
        });
        Self { exponent, tables }
    }

    /// The code that gives linear light `share` (clipped to `[0, 1]`) on each channel.
    #[inline]
    pub fn code(&self, share: LinearRgb) -> [f32; 3] {
        std::array::from_fn(|c| {
            let x = share[c].clamp(0.0, 1.0) as f32;
            // Below the table, and NaN: the power.
            if x.is_nan() || x < f32::from_bits((127 - ENCODER_OCTAVES) << 23) {
                return x.powf(self.exponent[c]);
            }
            // The bits past the table's 8 of mantissa place the light within its step.
            let bits = x.to_bits() - ((127 - ENCODER_OCTAVES) << 23);
            let k = (bits >> 15) as usize;
            let t = (bits & 0x7fff) as f32 / 32768.0;
            let table = &self.tables[c];
            match table.get(k + 1) {
                Some(next) => table[k] + (next - table[k]) * t,
                // Full light: the table's last entry, exactly 1.
                None => table[k],
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The table is the power within 1e-6 over the whole range of light for γ from 1 to 4, is
    /// exact at black and full light, and clips as [`Response::to_code`] does.
    #[test]
    fn encoder_is_the_power() {
        for g in [1.0, 1.8, 2.2, 2.6, 4.0] {
            let response = Response {
                gamma: [g, g, g],
                max_residual: [0.0; 3],
            };
            let encoder = response.encoder();
            let mut worst = 0.0f64;
            let mut light = 1.0f64;
            while light > 1e-12 {
                for share in [light, light * 0.6173, light * 0.5003] {
                    let want = share.powf(1.0 / g);
                    let got = f64::from(encoder.code(LinearRgb::splat(share))[1]);
                    worst = worst.max((got - want).abs());
                }
                light *= 0.93;
            }
            assert!(worst < 1e-6, "γ {g}: off by {worst:e}");
            let ends = |share: f64| encoder.code(LinearRgb::splat(share)).map(f32::to_bits);
            assert_eq!(ends(0.0), [0; 3], "γ {g}");
            assert_eq!(ends(1.0), [1f32.to_bits(); 3], "γ {g}");
            assert_eq!(ends(3.0), [1f32.to_bits(); 3], "γ {g}: clipped");
            assert_eq!(ends(-1.0), [0; 3], "γ {g}: clipped");
            assert!(encoder.code(LinearRgb::splat(f64::NAN))[0].is_nan());
        }
    }
}
