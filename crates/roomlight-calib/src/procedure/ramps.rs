//! Every projector's response ramp from the same few captures (hand-written): all show the
//! same uniform code at once, and each projector's share at that code is unmixed from the
//! means over the pixels it lights most, with the other projectors' light there known from
//! their white captures: `m_k = Σ_j A_kj s_j` per channel, `A_kj` the mean rise of projector
//! `j`'s white over projector `k`'s pixels, `s_j` its light share at the code (DESIGN §2:
//! light adds). `A` is diagonally dominant by the choice of pixels; a singular one is refused.

use crate::CalibError;
use crate::graycode::Correspondence;
use crate::image_io::LinearImage;
use roomlight_core::LinearRgb;

/// The camera pixels that measure projector `k`'s ramp: decoded for it, unclipped in its
/// white, and raised by its white at least as much as by all the others' together (`gains`:
/// each projector's white minus dark, intensities). Without any, its decoded unclipped ones.
pub(super) fn ramp_pixels(
    corr: &Correspondence,
    k: usize,
    gains: &[Vec<f32>],
    white: &LinearImage,
) -> Vec<usize> {
    let unclipped = |i: usize| {
        white
            .pixels
            .get(i)
            .is_some_and(|p| p.iter().all(|&v| v < 0.98))
    };
    let decoded: Vec<usize> = corr
        .map
        .iter()
        .enumerate()
        .filter(|(i, m)| m.is_some() && unclipped(*i))
        .map(|(i, _)| i)
        .collect();
    let own: Vec<usize> = decoded
        .iter()
        .copied()
        .filter(|&i| {
            let others: f32 = (0..gains.len())
                .filter(|&j| j != k)
                .map(|j| gains[j][i].max(0.0))
                .sum();
            gains[k][i] > others
        })
        .collect();
    if own.is_empty() { decoded } else { own }
}

/// Mean and standard error of `image − dark` over `pixels`, per channel.
fn rise(image: &LinearImage, dark: &LinearImage, pixels: &[usize]) -> (LinearRgb, LinearRgb) {
    let n = pixels.len().max(1) as f64;
    let (mut sum, mut sq) = (LinearRgb::ZERO, LinearRgb::ZERO);
    for &i in pixels {
        let v = LinearRgb(std::array::from_fn(|c| {
            f64::from(image.pixels[i][c] - dark.pixels[i][c])
        }));
        sum += v;
        sq += v.hadamard(v);
    }
    let mean = sum * (1.0 / n);
    let var = (sq * (1.0 / n) - mean.hadamard(mean)).map(|v| v.max(0.0));
    (mean, var.map(|v| (v / n).sqrt()))
}

/// One projector's ramp: light shares per level and their standard errors.
pub(super) type Ramp = (Vec<LinearRgb>, Vec<LinearRgb>);

/// Each projector's ramp as light shares with their standard errors, ends included (0 at
/// `dark`, 1 at its white): `levels[l]` every projector at the same inner code, `whites[k]`
/// and `pixels[k]` projector `k`'s ([`ramp_pixels`]). What [`crate::response::fit_response`]
/// takes.
pub(super) fn unmix(
    levels: &[LinearImage],
    dark: &LinearImage,
    whites: &[&LinearImage],
    pixels: &[Vec<usize>],
) -> Result<Vec<Ramp>, CalibError> {
    let n = whites.len();
    // a[k][j]: projector j's white over projector k's pixels.
    let a: Vec<Vec<(LinearRgb, LinearRgb)>> = (0..n)
        .map(|k| whites.iter().map(|w| rise(w, dark, &pixels[k])).collect())
        .collect();
    let mut out: Vec<Ramp> = (0..n)
        .map(|k| {
            let end = relative(a[k][k].1, a[k][k].0);
            (vec![LinearRgb::ZERO], vec![end])
        })
        .collect();
    for level in levels {
        let m: Vec<(LinearRgb, LinearRgb)> =
            (0..n).map(|k| rise(level, dark, &pixels[k])).collect();
        let mut shares = vec![LinearRgb::ZERO; n];
        for c in 0..3 {
            let matrix: Vec<Vec<f64>> = (0..n)
                .map(|k| (0..n).map(|j| a[k][j].0[c]).collect())
                .collect();
            let rhs: Vec<f64> = m.iter().map(|v| v.0[c]).collect();
            let s = solve(matrix, rhs).ok_or_else(|| CalibError::Invalid {
                field: "ramp",
                problem: format!(
                    "channel {c}: the projectors' lights cannot be told apart on the pixels each lights most"
                ),
            })?;
            for (share, v) in shares.iter_mut().zip(s) {
                share.0[c] = v;
            }
        }
        for (k, o) in out.iter_mut().enumerate() {
            o.0.push(shares[k]);
            o.1.push(relative(m[k].1, a[k][k].0));
        }
    }
    for (k, o) in out.iter_mut().enumerate() {
        o.0.push(LinearRgb::ONE);
        let end = o.1[0];
        o.1.push(end);
        // A projector with no pixel of its own: no light, which the fit refuses by name.
        if pixels[k].is_empty() {
            o.0.iter_mut().for_each(|v| *v = LinearRgb::ZERO);
        }
    }
    Ok(out)
}

/// `error / scale` per channel (a zero scale gives a huge error, never a division by zero).
fn relative(error: LinearRgb, scale: LinearRgb) -> LinearRgb {
    LinearRgb(std::array::from_fn(|c| {
        error.0[c] / scale.0[c].abs().max(f64::MIN_POSITIVE)
    }))
}

/// Solves `a x = b` by Gaussian elimination with partial pivoting; `None` when a pivot is
/// negligible (under 1e-12 of the largest entry) or the result is not finite.
fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    let scale = a.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    if n == 0 {
        return Some(Vec::new());
    }
    if scale.is_nan() || scale <= 0.0 {
        return None;
    }
    for col in 0..n {
        let pivot = (col..n).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() < 1e-12 * scale {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        for row in col + 1..n {
            let f = a[row][col] / a[col][col];
            let pivot_row = a[col].clone();
            for (x, p) in a[row].iter_mut().zip(&pivot_row).skip(col) {
                *x -= f * p;
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = vec![0.0; n];
    for row in (0..n).rev() {
        let s: f64 = (row + 1..n).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_small_system_and_refuses_a_singular_one() {
        let x = solve(vec![vec![2.0, 0.5], vec![0.25, 1.0]], vec![2.5, 1.25]).expect("solved");
        assert!(
            (x[0] - 1.0).abs() < 1e-12 && (x[1] - 1.0).abs() < 1e-12,
            "{x:?}"
        );
        assert!(solve(vec![vec![1.0, 2.0], vec![2.0, 4.0]], vec![1.0, 2.0]).is_none());
    }
}
