//! Resolving the bits a pixel cannot decide on its own because it straddles a stripe edge
//! (lens blur, a camera pixel spanning two projector pixels): per axis, every code that agrees
//! with the pixel's trusted bits is tried as "this projector pixel, perhaps mixed with the one
//! beside it", the differences are fitted to it by least squares, and the best fit is taken
//! only when it explains the differences to within their noise and no code more than one pixel
//! away explains them nearly as well. It owns that per-axis decision and the noise estimate it
//! needs; it must not know where the captures came from.

use super::{Axis, Manifest, Pair, Reading, gray_inverse};

/// At most this many untrusted bits per axis are enumerated (2⁸ codes); a pixel with more is
/// left to its neighbours.
const MAX_OPEN: usize = 8;
/// The best fit may leave at most this share of the signal a pixel of its direct light shows
/// on every bit (`n · ld²`), beyond the noise: a pixel across a depth edge leaves more. (Only
/// pixels beside decoded ones are resolved, see `fill`: on its own, a dim face that reflects
/// a bright one's codes can fit a wrong code this well.)
const FIT_RESIDUAL: f32 = 0.08;
/// The best fit must beat every code more than one pixel away by this many standard deviations
/// of the difference of their residuals.
const GAP_SIGMAS: f32 = 6.0;

/// The most bits per axis resolved (a side of [`super::MAX_SIDE`] needs 13).
const MAX_BITS: usize = 16;

/// Per bit, a value of one axis (signs, differences): fixed-size, no allocation per candidate.
type Bits = [f32; MAX_BITS];

/// The signs (±1) the encoded patterns of `readings` show at coordinate `v` (0 beyond them).
fn signs(manifest: &Manifest, axis: Axis, readings: &[&Reading], v: u32) -> Bits {
    let mut out = [0.0; MAX_BITS];
    for (o, r) in out.iter_mut().zip(readings) {
        *o = if manifest.encoded_bit(axis, r.bit, v) {
            1.0
        } else {
            -1.0
        };
    }
    out
}

/// Residual of the least-squares fit of `d` by `a·p + b·q` with `a ≥ b ≥ 0`, where `p` and `q`
/// are the sign patterns of a projector pixel and of the one beside it (the camera pixel sees
/// mostly the first). Bits where they agree show `a + b`, the pixel's whole direct light, held
/// within `[ld/2, ld]` of the direct light `ld` measured over every pair (so that a pixel
/// whose differences all vanish fits only a code whose every bit flips beside it); bits where
/// they differ show `a − b`.
fn mixed_fit(d: &[f32], p: &Bits, q: &Bits, ld: f32) -> Fit {
    let (mut same, mut ns, mut diff, mut nd) = (0.0f32, 0usize, 0.0f32, 0usize);
    for ((d, p), q) in d.iter().zip(p).zip(q) {
        if same_sign(*p, *q) {
            same += d * p;
            ns += 1;
        } else {
            diff += d * p;
            nd += 1;
        }
    }
    // Means of the projected differences; an empty set fits nothing (0 bits, no residual).
    let u = if ns == 0 { ld } else { same / ns as f32 }.clamp(0.5 * ld, ld);
    let w = if nd == 0 { 0.0 } else { diff / nd as f32 }.clamp(0.0, u);
    let mut predicted = [0.0; MAX_BITS];
    for ((e, p), q) in predicted.iter_mut().zip(p).zip(q).take(d.len()) {
        *e = if same_sign(*p, *q) { u * p } else { w * p };
    }
    let residual = d.iter().zip(&predicted).map(|(d, e)| (d - e).powi(2)).sum();
    Fit {
        residual,
        shared_edge: ns == 0,
        predicted,
    }
}

/// Whether two signs (±1) are the same.
fn same_sign(p: f32, q: f32) -> bool {
    (p > 0.0) == (q > 0.0)
}

/// A least-squares fit of [`mixed_fit`].
#[derive(Debug, Clone)]
struct Fit {
    residual: f32,
    /// Every bit differs between the two mixed pixels (an edge every pattern shares).
    shared_edge: bool,
    /// The differences it predicts (0 beyond the axis's bits).
    predicted: Bits,
}

/// One candidate of [`resolve_axis`]: its coordinate and its best mixed fit.
#[derive(Debug, Clone)]
struct Candidate {
    v: u32,
    fit: Fit,
}

/// The coordinate on `axis` of a pixel whose readings of that axis (most significant first)
/// are `readings`, its direct light `ld` and difference noise `sigma`: among the candidates
/// (every code that agrees with the trusted bits, with at most [`MAX_OPEN`] untrusted ones; or,
/// with `near`, every coordinate in that range that agrees with them, of which only one on an
/// edge every pattern shares is taken), the one whose mixed fit with a neighbour leaves the
/// least residual, with its confidence in `[0, 1]` (its lead over
/// the best candidate more than one pixel away, over `n·ld²`). `None` when the fit leaves more
/// than noise and [`FIT_RESIDUAL`], or a rival more than one pixel away fits nearly as well.
pub(super) fn resolve_axis(
    manifest: &Manifest,
    axis: Axis,
    readings: &[&Reading],
    ld: f32,
    sigma: f32,
    near: Option<(i64, i64)>,
) -> Option<(u32, f32)> {
    let n = readings.len();
    let size = manifest.cells(axis);
    if n == 0 || n > MAX_BITS || ld.is_nan() || ld <= 0.0 || !sigma.is_finite() {
        return None;
    }
    let d: Vec<f32> = readings.iter().map(|r| r.d).collect();
    if d.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let agrees = |v: u32| {
        readings.iter().all(|r| {
            r.trusted
                .is_none_or(|t| manifest.encoded_bit(axis, r.bit, v) == t)
        })
    };
    let coords: Vec<u32> = match near {
        Some((lo, hi)) => (lo.max(0)..=hi.min(i64::from(size) - 1))
            .map(|v| v as u32)
            .filter(|&v| agrees(v))
            .collect(),
        None => enumerate(manifest, axis, readings)?,
    };
    let pattern = |v: u32| signs(manifest, axis, readings, v);
    let candidates: Vec<Candidate> = coords
        .into_iter()
        .map(|v| {
            let p = pattern(v);
            let mut fit = mixed_fit(&d, &p, &p, ld);
            for w in [v.checked_sub(1), v.checked_add(1).filter(|w| *w < size)]
                .into_iter()
                .flatten()
            {
                let other = mixed_fit(&d, &p, &pattern(w), ld);
                if other.residual < fit.residual {
                    fit = other;
                }
            }
            Candidate { v, fit }
        })
        .collect();
    let best = candidates
        .iter()
        .min_by(|a, b| a.fit.residual.total_cmp(&b.fit.residual))?;
    let signal = n as f32 * ld * ld;
    // Noise alone leaves about n·σ² (a χ² of n degrees of freedom; 3 + 3√(2n) of margin).
    let noise = sigma * sigma * (n as f32 + 3.0 + 3.0 * (2.0 * n as f32).sqrt());
    // Within the neighbours' range only a pixel on an edge every pattern shares is taken: its
    // differences vanish and say nothing of which such edge it is on, which the neighbours do.
    if best.fit.residual > noise + FIT_RESIDUAL * signal
        || (near.is_some() && !best.fit.shared_edge)
    {
        return None;
    }
    let worst = lead_sigmas(&candidates, best, sigma);
    (worst >= GAP_SIGMAS).then(|| (best.v, (worst / (4.0 * GAP_SIGMAS)).min(1.0)))
}

/// The least lead, in noise standard deviations, of `best`'s fit over the candidates more
/// than one pixel away (infinite without such rivals): residuals of two fits differ by
/// `2·Σ (e − e')·noise`, of standard deviation `2σ·|e − e'|`.
fn lead_sigmas(candidates: &[Candidate], best: &Candidate, sigma: f32) -> f32 {
    let mut worst = f32::INFINITY;
    for c in candidates.iter().filter(|c| c.v.abs_diff(best.v) > 1) {
        let apart: f32 = c
            .fit
            .predicted
            .iter()
            .zip(&best.fit.predicted)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f32>()
            .sqrt();
        let lead = c.fit.residual - best.fit.residual;
        // Two fits that predict the same differences cannot be told apart: no lead.
        let sigmas = if apart > 0.0 {
            lead / (2.0 * sigma * apart).max(f32::MIN_POSITIVE)
        } else {
            0.0
        };
        worst = worst.min(sigmas);
    }
    worst
}

/// Both axes of a pixel resolved separately ([`resolve_axis`]): within the range `near` gives
/// (on an edge every pattern shares, which the neighbours place), else on its own (within a
/// pixel of that range). The confidence is the smaller, halved (it ranks below a pixel whose
/// every bit was decided).
pub(super) fn resolve_pixel(
    manifest: &Manifest,
    readings: &[Reading],
    ld: f32,
    near: Option<[(i64, i64); 2]>,
) -> Option<((u32, u32), f32)> {
    let sigma = readings.iter().map(|r| r.sigma).sum::<f32>() / readings.len().max(1) as f32;
    let mut out = [(0u32, 0f32); 2];
    for (k, axis) in [Axis::Column, Axis::Row].into_iter().enumerate() {
        let ours: Vec<&Reading> = readings.iter().filter(|r| r.axis == axis).collect();
        let range = near.map(|n| n[k]);
        // On a shared edge within the neighbours' range (cheap: a few candidates), else on its
        // own within a pixel of that range.
        let beside = range.and_then(|r| resolve_axis(manifest, axis, &ours, ld, sigma, Some(r)));
        out[k] = match beside {
            Some(found) => found,
            None => resolve_axis(manifest, axis, &ours, ld, sigma, None).filter(|(v, _)| {
                range.is_none_or(|(lo, hi)| (lo - 1..=hi + 1).contains(&i64::from(*v)))
            })?,
        };
    }
    Some(((out[0].0, out[1].0), 0.5 * out[0].1.min(out[1].1)))
}

/// Every coordinate whose code agrees with the trusted readings (most significant first), at
/// most 2^[`MAX_OPEN`] of them; `None` with more untrusted bits.
fn enumerate(manifest: &Manifest, axis: Axis, readings: &[&Reading]) -> Option<Vec<u32>> {
    let open: Vec<usize> = (0..readings.len())
        .filter(|&k| readings[k].trusted.is_none())
        .collect();
    if open.len() > MAX_OPEN {
        return None;
    }
    let bits = readings.len() as u32;
    let base = manifest.base_bit(bits).map(|b| b as usize);
    let size = manifest.cells(axis);
    let mut out = Vec::with_capacity(1 << open.len());
    for mask in 0u32..(1 << open.len()) {
        let mut encoded: Vec<bool> = readings
            .iter()
            .map(|r| r.trusted.unwrap_or(false))
            .collect();
        for (j, &k) in open.iter().enumerate() {
            encoded[k] = mask >> j & 1 == 1;
        }
        let mut code = 0u32;
        for (k, &e) in encoded.iter().enumerate() {
            let g = match base {
                Some(b) if b != k => e != encoded[b],
                _ => e,
            };
            code = (code << 1) | u32::from(g);
        }
        let v = gray_inverse(code);
        if v < size {
            out.push(v);
        }
    }
    Some(out)
}

/// Per pixel, the noise standard deviation of one pattern − inverse difference, measured from
/// the captures themselves: light adds, so every pattern and its inverse sum to white, and
/// `pattern + inverse − white − black` varies only by noise from pair to pair (its variance is
/// about twice a difference's). Averaged over the 3×3 neighbourhood; 0 with fewer than two
/// pairs.
pub(super) fn measured_noise(
    w: usize,
    h: usize,
    white: &[f32],
    black: &[f32],
    pairs: &[Pair],
) -> Vec<f32> {
    let m = pairs.len();
    let variance: Vec<f32> = (0..w * h)
        .map(|i| {
            if m < 2 {
                return 0.0;
            }
            let lit = white[i] - black[i];
            let r = |(_, _, p, q): &Pair| p[i] + q[i] - lit;
            let mean = pairs.iter().map(r).sum::<f32>() / m as f32;
            pairs.iter().map(|pq| (r(pq) - mean).powi(2)).sum::<f32>() / (m - 1) as f32
        })
        .collect();
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let (mut sum, mut count) = (0.0f32, 0usize);
            for yy in y.saturating_sub(1)..=(y + 1).min(h - 1) {
                for xx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                    sum += variance[yy * w + xx];
                    count += 1;
                }
            }
            // NaN (a corrupt capture) stays NaN: such pixels are not reached.
            (0.5 * sum / count.max(1) as f32).sqrt()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A reading of `d` with nothing trusted.
    fn open(bit: u32, d: f32) -> Reading {
        Reading {
            axis: Axis::Column,
            bit,
            d,
            sigma: 0.01,
            trusted: None,
        }
    }

    #[test]
    fn a_pixel_on_a_shared_edge_is_placed_by_its_neighbours_and_only_there() {
        let manifest = Manifest::new(64, 4).expect("manifest");
        // XOR-04's base bit (4 of 6) flips between 5 and 6 and with it every pattern: a
        // camera pixel half on each shows no difference at all.
        let flips = |v: u32| {
            (0..6).all(|b| {
                manifest.encoded_bit(Axis::Column, b, v)
                    != manifest.encoded_bit(Axis::Column, b, v + 1)
            })
        };
        assert!(flips(5) && flips(9) && !flips(6) && !flips(7));
        let readings: Vec<Reading> = (0..6).map(|b| open(b, 0.0)).collect();
        let ours: Vec<&Reading> = readings.iter().collect();
        // On its own it could be on any shared edge: unknown.
        assert_eq!(
            resolve_axis(&manifest, Axis::Column, &ours, 0.5, 0.01, None),
            None
        );
        // Between neighbours at 4 and 7, it is on the edge 5|6.
        let (v, _) =
            resolve_axis(&manifest, Axis::Column, &ours, 0.5, 0.01, Some((4, 7))).expect("placed");
        assert!(v == 5 || v == 6, "{v}");
        // Neighbours spanning two shared edges (5|6 and 9|10) cannot place it.
        assert_eq!(
            resolve_axis(&manifest, Axis::Column, &ours, 0.5, 0.01, Some((4, 10))),
            None
        );
        // A pixel at 7, a quarter of the way to 8, shows its own code (weaker on the bits that
        // flip between 7 and 8) and is resolved on its own.
        let readings: Vec<Reading> = (0..6)
            .map(|b| {
                let (a, c) = (
                    manifest.encoded_bit(Axis::Column, b, 7),
                    manifest.encoded_bit(Axis::Column, b, 8),
                );
                let s = |on: bool| if on { 1.0 } else { -1.0 };
                open(b, 0.5 * (0.75 * s(a) + 0.25 * s(c)))
            })
            .collect();
        let ours: Vec<&Reading> = readings.iter().collect();
        let (v, c) =
            resolve_axis(&manifest, Axis::Column, &ours, 0.5, 0.01, None).expect("resolved");
        assert_eq!(v, 7);
        assert!(c > 0.0 && c <= 1.0, "{c}");
    }

    #[test]
    fn the_noise_is_measured_from_pattern_plus_inverse_against_white() {
        // One pixel, white 1, black 0; pairs whose sum strays by ±e from white: the sum's
        // spread is e (about twice a difference's variance), so a difference's σ is e/√2.
        let e = 0.02f32;
        let (high, low, inverse) = ([0.7 + e], [0.7 - e], [0.3]);
        let pairs: Vec<Pair> = (0..8)
            .map(|k| {
                let p: &[f32] = if k % 2 == 0 { &high } else { &low };
                (Axis::Column, k, p, &inverse[..])
            })
            .collect();
        let sigma = measured_noise(1, 1, &[1.0], &[0.0], &pairs)[0];
        // Sample variance over 8 pairs of ±e: e²·8/7.
        let expected = (0.5 * e * e * 8.0 / 7.0).sqrt();
        assert!((sigma - expected).abs() < 1e-6, "{sigma} vs {expected}");
        // Fewer than two pairs: no estimate (0).
        assert!(measured_noise(1, 1, &[1.0], &[0.0], &pairs[..1])[0].abs() < f32::EPSILON);
    }
}
