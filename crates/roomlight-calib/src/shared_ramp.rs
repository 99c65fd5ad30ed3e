//! A response ramp shown by every projector at once (DESIGN §4.3): one capture per level for
//! the whole room instead of one per projector and level.
//!
//! Light adds, so at camera pixel `i` a capture of every projector at one uniform code is
//! `dark(i) + Σ_k s_k · (white_k(i) − dark(i))`, `white_k` projector `k` alone at full white
//! (the footprint captures) and `s_k` its share of that white at the code, per channel. With
//! the whites known the shares are a linear least-squares problem of one unknown per
//! projector, over the hundreds of thousands of pixels the projectors were decoded on; where
//! footprints overlap the whites tell the projectors apart, as they do where they do not.

use crate::CalibError;
use crate::graycode::Correspondence;
use crate::image_io::LinearImage;
use nalgebra::{DMatrix, DVector, SymmetricEigen};
use roomlight_core::LinearRgb;

/// A camera value at or above this is taken as clipped, and its pixel left out (as
/// [`crate::response::footprint_ramp`] leaves out pixels clipped at full white).
const CLIPPED: f32 = 0.98;

/// Fewest usable pixels per projector in the fit.
const MIN_PIXELS: usize = 16;

/// The smallest eigenvalue of the normal matrix scaled to a unit diagonal below which two
/// projectors' whites are too alike (over the usable pixels) to share the capture: about a
/// correlation of 0.9995 between two of them.
const MIN_SEPARATION: f64 = 1e-3;

/// Each projector's share of its own white, per channel, in `level`: a capture of every
/// projector of `whites` at one uniform code, `dark` the room with all of them black,
/// `decoded[k]` where projector `k` (called `names[k]` in errors) was decoded. Pixels where
/// any of the images clips are left out.
///
/// Refused (naming the projector) when the images differ in size, when a
/// projector has fewer than [`MIN_PIXELS`] usable pixels, when two projectors' whites cannot
/// be told apart over them, or when a share comes out non-finite; the caller then shows the
/// levels one projector at a time.
pub fn shared_level(
    level: &LinearImage,
    dark: &LinearImage,
    whites: &[&LinearImage],
    decoded: &[&Correspondence],
    names: &[&str],
) -> Result<Vec<LinearRgb>, CalibError> {
    let n = level.pixels.len();
    let k_count = whites.len();
    let same = |w: u32, h: u32| w == level.width && h == level.height;
    if whites.is_empty()
        || decoded.len() != k_count
        || names.len() != k_count
        || !same(dark.width, dark.height)
        || whites.iter().any(|w| !same(w.width, w.height))
        || decoded.iter().any(|d| !same(d.width, d.height))
        || dark.pixels.len() != n
        || whites.iter().any(|w| w.pixels.len() != n)
        || decoded.iter().any(|d| d.map.len() != n)
    {
        return Err(invalid(format!(
            "{k_count} whites, {} decoded maps and {} names against a {}×{} level capture: expected one of each per projector, all of the capture's size",
            decoded.len(),
            names.len(),
            level.width,
            level.height
        )));
    }
    let clipped = |img: &LinearImage, i: usize| img.pixels[i].iter().any(|&v| v >= CLIPPED);
    let mut normal = [
        DMatrix::<f64>::zeros(k_count, k_count),
        DMatrix::zeros(k_count, k_count),
        DMatrix::zeros(k_count, k_count),
    ];
    let mut rhs = [
        DVector::<f64>::zeros(k_count),
        DVector::zeros(k_count),
        DVector::zeros(k_count),
    ];
    let mut used = vec![0usize; k_count];
    let mut white = vec![[0.0f64; 3]; k_count];
    for i in 0..n {
        if !decoded.iter().any(|d| d.map[i].is_some())
            || clipped(level, i)
            || clipped(dark, i)
            || whites.iter().any(|w| clipped(w, i))
        {
            continue;
        }
        for (k, d) in decoded.iter().enumerate() {
            used[k] += usize::from(d.map[i].is_some());
        }
        let black = dark.pixels[i];
        for (k, w) in whites.iter().enumerate() {
            white[k] = std::array::from_fn(|c| f64::from(w.pixels[i][c] - black[c]));
        }
        for c in 0..3 {
            let y = f64::from(level.pixels[i][c] - black[c]);
            for a in 0..k_count {
                rhs[c][a] += white[a][c] * y;
                for b in a..k_count {
                    normal[c][(a, b)] += white[a][c] * white[b][c];
                }
            }
        }
    }
    if let Some(k) = used.iter().position(|&u| u < MIN_PIXELS) {
        return Err(invalid(format!(
            "{}: {} usable camera pixels (decoded, nothing clipped), expected at least {MIN_PIXELS}",
            names[k], used[k]
        )));
    }
    let mut shares = vec![LinearRgb::ZERO; k_count];
    for c in 0..3 {
        let m = &mut normal[c];
        for a in 0..k_count {
            for b in 0..a {
                m[(a, b)] = m[(b, a)];
            }
        }
        // Scaled to a unit diagonal, so the test of separation does not depend on how bright
        // each projector is. A zero diagonal (a white that adds nothing) is refused here.
        let scale: Vec<f64> = (0..k_count).map(|a| m[(a, a)].sqrt()).collect();
        if let Some(k) = scale.iter().position(|s| !(*s > 0.0 && s.is_finite())) {
            return Err(invalid(format!(
                "{}: its white adds no light on channel {c} over the usable pixels",
                names[k]
            )));
        }
        let scaled = DMatrix::from_fn(k_count, k_count, |a, b| m[(a, b)] / (scale[a] * scale[b]));
        let eigen = SymmetricEigen::new(scaled.clone());
        let (low, at) = eigen
            .eigenvalues
            .iter()
            .enumerate()
            .map(|(j, v)| (*v, j))
            .fold(
                (f64::INFINITY, 0),
                |best, e| if e.0 < best.0 { e } else { best },
            );
        // NaN (from a NaN pixel) is refused too.
        if low.is_nan() || low <= MIN_SEPARATION {
            // The projector that weighs most in the nearly shared direction.
            let k = eigen.eigenvectors.column(at).iamax();
            return Err(invalid(format!(
                "{}: its white cannot be told apart from another's on channel {c} (separation {low:.1e}, expected above {MIN_SEPARATION:.0e})",
                names[k]
            )));
        }
        let b = DVector::from_fn(k_count, |a, _| rhs[c][a] / scale[a]);
        let solved = scaled.cholesky().map(|ch| ch.solve(&b)).ok_or_else(|| {
            invalid(format!(
                "channel {c}: the normal matrix is not positive definite"
            ))
        })?;
        for (k, share) in shares.iter_mut().enumerate() {
            let s = solved[k] / scale[k];
            if !s.is_finite() {
                return Err(invalid(format!("{}: share {s} on channel {c}", names[k])));
            }
            share.0[c] = s;
        }
    }
    Ok(shares)
}

fn invalid(problem: String) -> CalibError {
    CalibError::Invalid {
        field: "shared ramp",
        problem,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A correspondence decoded (at a projector pixel that does not matter here) where `at`.
    fn decoded_where(w: u32, h: u32, at: impl Fn(usize) -> bool) -> Correspondence {
        let n = (w * h) as usize;
        Correspondence {
            width: w,
            height: h,
            projector_width: 64,
            projector_height: 64,
            map: (0..n).map(|i| at(i).then_some((0, 0))).collect(),
            confidence: vec![1.0; n],
            direct: vec![0.0; n],
            global: vec![0.0; n],
            reach: 0.0,
        }
    }

    /// Three projectors on a 96×64 camera whose footprints overlap in pairs, each with its own
    /// gamma per channel and a floor of inter-reflected light everywhere; the level capture is
    /// their sum at code 0.4 with read noise. The shares come back within 1% of `0.4^γ`.
    #[test]
    fn overlapping_projectors_share_a_level() {
        let (w, h) = (96u32, 64u32);
        let n = (w * h) as usize;
        let gammas = [[2.2, 2.1, 2.3], [1.8, 2.0, 2.6], [2.4, 2.4, 2.4]];
        // Projector k lights columns [32k − 8, 32k + 40) directly, and 5% of its light is
        // reflected over the whole image; the dark room is 0.02.
        let direct = |k: usize, x: u32| {
            let x = i64::from(x);
            let from = 32 * k as i64 - 8;
            (from..from + 48).contains(&x)
        };
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut noise = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.004
        };
        let dark = LinearImage {
            width: w,
            height: h,
            pixels: vec![[0.02; 3]; n],
        };
        let light = |k: usize, i: usize, c: usize| {
            let x = i as u32 % w;
            let base = [0.5, 0.4, 0.3][c] * (1.0 + 0.3 * (i as f64 * 0.37).sin());
            0.05 * 0.3 + if direct(k, x) { base } else { 0.0 }
        };
        let whites: Vec<LinearImage> = (0..3)
            .map(|k| LinearImage {
                width: w,
                height: h,
                pixels: (0..n)
                    .map(|i| std::array::from_fn(|c| (0.02 + light(k, i, c) + noise()) as f32))
                    .collect(),
            })
            .collect();
        let code = 0.4f64;
        let level = LinearImage {
            width: w,
            height: h,
            pixels: (0..n)
                .map(|i| {
                    std::array::from_fn(|c| {
                        let sum: f64 = (0..3)
                            .map(|k| code.powf(gammas[k][c]) * light(k, i, c))
                            .sum();
                        (0.02 + sum + noise()) as f32
                    })
                })
                .collect(),
        };
        let decoded: Vec<Correspondence> = (0..3)
            .map(|k| decoded_where(w, h, |i| direct(k, i as u32 % w)))
            .collect();
        let shares = shared_level(
            &level,
            &dark,
            &whites.iter().collect::<Vec<_>>(),
            &decoded.iter().collect::<Vec<_>>(),
            &["a", "b", "c"],
        )
        .expect("shares");
        for k in 0..3 {
            for c in 0..3 {
                let want = code.powf(gammas[k][c]);
                assert!(
                    (shares[k][c] / want - 1.0).abs() < 0.01,
                    "projector {k} channel {c}: {} against {want}",
                    shares[k][c]
                );
            }
        }
        // Two projectors with the same white cannot be told apart: refused, not guessed.
        let twins = [&whites[0], &whites[0]];
        let err = shared_level(
            &level,
            &dark,
            &twins,
            &[&decoded[0], &decoded[0]],
            &["a", "b"],
        )
        .expect_err("identical whites");
        assert!(err.to_string().contains("cannot be told apart"), "{err}");
        // A projector with no decoded pixel is refused by name.
        let none = decoded_where(w, h, |_| false);
        let err = shared_level(
            &level,
            &dark,
            &[&whites[0], &whites[1]],
            &[&decoded[0], &none],
            &["a", "b"],
        )
        .expect_err("nothing decoded");
        assert!(
            err.to_string().contains("b: 0 usable camera pixels"),
            "{err}"
        );
    }
}
