//! Light-weighted centroids of projected spots (issue 21, item 7): a defocused projector (the
//! large aperture) blurs each pixel over many camera pixels, so where it lands is measured by
//! the centre of its light rather than by decoding stripes. A spot is a connected set of camera
//! pixels whose light rises above a floor; its centroid weights each pixel by its light above
//! that floor, so that a symmetric blur is centred where the sharp image would be.

use crate::CalibError;
use std::collections::VecDeque;

/// One spot of light in a camera image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spot {
    /// Light-weighted centroid, in camera pixels (pixel `(x, y)` covers `[x, x + 1)`, so a
    /// pixel's centre is at `x + 0.5`).
    pub centroid: [f64; 2],
    /// Light above the floor, summed over the spot.
    pub light: f64,
    /// Camera pixels in the spot.
    pub pixels: usize,
}

/// The spots in `light` (one value per camera pixel, row-major, `width` wide, e.g. a capture of
/// some projector pixels minus a black capture): the 8-connected regions where the light
/// exceeds `floor`, each with its light-weighted centroid (weights `light − floor`). Regions
/// of fewer than `min_pixels` pixels are left out (noise). Light that is not finite, a size
/// that does not divide the image, or a floor that is not finite is refused.
pub fn spots(
    light: &[f32],
    width: usize,
    floor: f32,
    min_pixels: usize,
) -> Result<Vec<Spot>, CalibError> {
    if !floor.is_finite() {
        return Err(CalibError::Invalid {
            field: "spot floor",
            problem: format!("{floor} is not finite"),
        });
    }
    spots_over(light, width, &vec![floor; light.len()], min_pixels)
}

/// [`spots`] with a floor per pixel (e.g. [`local_floor`]): a region holds the pixels above
/// their own floor, each weighted by its light above it. A floor of another size than the
/// light, or not finite anywhere, is refused.
pub fn spots_over(
    light: &[f32],
    width: usize,
    floor: &[f32],
    min_pixels: usize,
) -> Result<Vec<Spot>, CalibError> {
    check_image(light, width)?;
    if floor.len() != light.len() {
        return Err(CalibError::Invalid {
            field: "spot floor",
            problem: format!("{} values for {} pixels", floor.len(), light.len()),
        });
    }
    if let Some(i) = floor.iter().position(|v| !v.is_finite()) {
        return Err(CalibError::Invalid {
            field: "spot floor",
            problem: format!("{} at pixel ({}, {})", floor[i], i % width, i / width),
        });
    }
    let height = light.len() / width;
    let above = |i: usize| light[i] > floor[i];
    let mut seen = vec![false; light.len()];
    let mut out = Vec::new();
    let mut queue = VecDeque::new();
    for start in 0..light.len() {
        if seen[start] || !above(start) {
            continue;
        }
        seen[start] = true;
        queue.push_back(start);
        let (mut sum, mut sx, mut sy, mut n) = (0.0f64, 0.0f64, 0.0f64, 0usize);
        while let Some(i) = queue.pop_front() {
            let (x, y) = (i % width, i / width);
            let w = f64::from(light[i] - floor[i]);
            sum += w;
            sx += w * (x as f64 + 0.5);
            sy += w * (y as f64 + 0.5);
            n += 1;
            for ny in y.saturating_sub(1)..(y + 2).min(height) {
                for nx in x.saturating_sub(1)..(x + 2).min(width) {
                    let j = ny * width + nx;
                    if !seen[j] && above(j) {
                        seen[j] = true;
                        queue.push_back(j);
                    }
                }
            }
        }
        // sum > 0: every pixel in the region is above its floor.
        if n >= min_pixels && sum > 0.0 {
            out.push(Spot {
                centroid: [sx / sum, sy / sum],
                light: sum,
                pixels: n,
            });
        }
    }
    Ok(out)
}

/// Spots whose centroids lie within `radius` of each other (through others within `radius`,
/// single linkage) merged into one: the light-weighted mean of their centroids, their light and
/// pixels summed. A footprint split into pieces by an edge or by noise is then one spot again,
/// as long as footprints shown together lie further apart than `radius`. Merged spots come in
/// the order of their first piece.
pub fn merge_spots(spots: &[Spot], radius: f64) -> Vec<Spot> {
    let n = spots.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for i in 0..n {
        for j in i + 1..n {
            let (a, b) = (spots[i].centroid, spots[j].centroid);
            if (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) <= radius * radius {
                let (ri, rj) = (root(&mut parent, i), root(&mut parent, j));
                parent[ri.max(rj)] = ri.min(rj);
            }
        }
    }
    // Per group: light-weighted sums, light, pixels, and the first piece's centroid.
    type Group = (f64, f64, f64, usize, [f64; 2]);
    let mut acc: Vec<Option<Group>> = vec![None; n];
    for (i, s) in spots.iter().enumerate() {
        let r = root(&mut parent, i);
        let a = acc[r].get_or_insert((0.0, 0.0, 0.0, 0, s.centroid));
        a.0 += s.light * s.centroid[0];
        a.1 += s.light * s.centroid[1];
        a.2 += s.light;
        a.3 += s.pixels;
    }
    acc.into_iter()
        .flatten()
        .map(|(sx, sy, light, pixels, first)| Spot {
            // Spots carry light above a floor; a group without any keeps its first centroid.
            centroid: if light > 0.0 {
                [sx / light, sy / light]
            } else {
                first
            },
            light,
            pixels,
        })
        .collect()
}

/// Light of `width`-wide rows, finite everywhere.
fn check_image(light: &[f32], width: usize) -> Result<(), CalibError> {
    if width == 0 || !light.len().is_multiple_of(width) {
        return Err(CalibError::Invalid {
            field: "spot image",
            problem: format!("{} pixels do not make rows of {width}", light.len()),
        });
    }
    if let Some(i) = light.iter().position(|v| !v.is_finite()) {
        return Err(CalibError::Invalid {
            field: "spot image",
            problem: format!("light {} at pixel ({}, {})", light[i], i % width, i / width),
        });
    }
    Ok(())
}

/// A floor per pixel for [`spots_over`] that follows each spot's own brightness: `share` of
/// the brightest light within `radius` pixels (a square window), never under `least` (the
/// noise). A spot far dimmer than the brightest in the image (a defocused projector's light
/// spread over a wide blur disc) then keeps its own core above its own floor, where one floor
/// for the whole image drops it; spots further apart than `radius` do not raise each other's
/// floor. `share` outside `[0, 1]` or a `least` that is not finite is refused.
///
/// The window maximum is the van Herk–Gil-Werman filter, one pass per axis: hand-written
/// because the image crates' grey-scale dilations work on integer pixels, not on light.
pub fn local_floor(
    light: &[f32],
    width: usize,
    radius: usize,
    share: f32,
    least: f32,
) -> Result<Vec<f32>, CalibError> {
    check_image(light, width)?;
    if !(0.0..=1.0).contains(&share) {
        return Err(CalibError::Invalid {
            field: "spot floor share",
            problem: format!("{share}; expected a share in [0, 1]"),
        });
    }
    if !least.is_finite() {
        return Err(CalibError::Invalid {
            field: "spot floor",
            problem: format!("least {least} is not finite"),
        });
    }
    let height = light.len() / width;
    let mut rows = vec![0.0f32; light.len()];
    for (src, dst) in light.chunks(width).zip(rows.chunks_mut(width)) {
        dst.copy_from_slice(&window_max(src, radius));
    }
    let mut out = vec![0.0f32; light.len()];
    let mut column = vec![0.0f32; height];
    for x in 0..width {
        for (y, c) in column.iter_mut().enumerate() {
            *c = rows[y * width + x];
        }
        for (y, m) in window_max(&column, radius).into_iter().enumerate() {
            out[y * width + x] = (share * m).max(least);
        }
    }
    Ok(out)
}

/// The maximum of `values` over `[i − radius, i + radius]` (clipped to the slice) for every
/// `i`, in three passes whatever the radius (van Herk–Gil-Werman).
fn window_max(values: &[f32], radius: usize) -> Vec<f32> {
    let n = values.len();
    let k = 2 * radius + 1;
    // Padded by `radius` on each side with −∞, up to whole blocks of `k`.
    let len = (n + 2 * radius).div_ceil(k) * k;
    let padded = |j: usize| {
        j.checked_sub(radius)
            .and_then(|i| values.get(i))
            .copied()
            .unwrap_or(f32::NEG_INFINITY)
    };
    let mut from_start = vec![f32::NEG_INFINITY; len];
    let mut to_end = vec![f32::NEG_INFINITY; len];
    for j in 0..len {
        from_start[j] = if j % k == 0 {
            padded(j)
        } else {
            from_start[j - 1].max(padded(j))
        };
    }
    for j in (0..len).rev() {
        to_end[j] = if j % k == k - 1 {
            padded(j)
        } else {
            to_end[j + 1].max(padded(j))
        };
    }
    // The window of `i` is padded `i..=i + 2·radius`: it spans at most two blocks.
    (0..n)
        .map(|i| to_end[i].max(from_start[i + 2 * radius]))
        .collect()
}

/// The camera noise in `light` (a difference of two captures, mostly dark): 1.4826 × the median
/// absolute deviation from the median, the standard deviation of Gaussian noise, which the few
/// lit pixels do not move. 0 for no light.
pub fn noise_sigma(light: &[f32]) -> f32 {
    if light.is_empty() {
        return 0.0;
    }
    let mut v: Vec<f32> = light.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    let median = *v.select_nth_unstable_by(mid, f32::total_cmp).1;
    for x in &mut v {
        *x = (*x - median).abs();
    }
    1.4826 * *v.select_nth_unstable_by(mid, f32::total_cmp).1
}

/// Where each block of `block`×`block` projector pixels lands in the camera image according to
/// a correspondence (camera pixel → projector pixel index, row-major, `projector_width` wide):
/// the mean centre of the camera pixels mapped into the block, and how many there are (`None`
/// for a block no camera pixel maps into). Blocks are numbered row-major over the projector.
pub fn block_centres(
    map: &[Option<u32>],
    camera_width: usize,
    (projector_width, projector_height): (u32, u32),
    block: u32,
) -> Vec<Option<([f64; 2], usize)>> {
    let block = block.max(1);
    let (bw, bh) = (
        projector_width.div_ceil(block) as usize,
        projector_height.div_ceil(block) as usize,
    );
    let mut acc = vec![(0.0f64, 0.0f64, 0usize); bw * bh];
    for (i, m) in map.iter().enumerate() {
        let Some(p) = m else { continue };
        let (x, y) = (p % projector_width, p / projector_width);
        if y >= projector_height || camera_width == 0 {
            continue;
        }
        let b = (y / block) as usize * bw + (x / block) as usize;
        acc[b].0 += (i % camera_width) as f64 + 0.5;
        acc[b].1 += (i / camera_width) as f64 + 0.5;
        acc[b].2 += 1;
    }
    acc.into_iter()
        .map(|(sx, sy, n)| (n > 0).then(|| ([sx / n as f64, sy / n as f64], n)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A disc of radius `r` around `(cx, cy)`, blurred by a Gaussian of σ `blur`, sampled at
    /// pixel centres over `w`×`h`, plus a deterministic ripple of `noise` amplitude.
    fn blurred_disc(w: usize, h: usize, (cx, cy): (f64, f64), r: f64, blur: f64) -> Vec<f32> {
        // The disc's indicator convolved with the Gaussian, by summing sub-samples of the disc.
        let mut img = vec![0.0f32; w * h];
        let sub = 4;
        let reach = (r + 4.0 * blur).ceil() as i64;
        let mut disc = Vec::new();
        for j in -(r as i64 + 1) * sub..=(r as i64 + 1) * sub {
            for i in -(r as i64 + 1) * sub..=(r as i64 + 1) * sub {
                let (dx, dy) = (i as f64 / sub as f64, j as f64 / sub as f64);
                if dx * dx + dy * dy <= r * r {
                    disc.push((cx + dx, cy + dy));
                }
            }
        }
        let norm = 1.0 / disc.len() as f64;
        for y in 0..h {
            for x in 0..w {
                let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                if (px - cx).abs() > reach as f64 || (py - cy).abs() > reach as f64 {
                    continue;
                }
                let v: f64 = disc
                    .iter()
                    .map(|(dx, dy)| {
                        let d2 = (px - dx).powi(2) + (py - dy).powi(2);
                        (-d2 / (2.0 * blur * blur)).exp()
                    })
                    .sum();
                img[y * w + x] = (v * norm) as f32;
            }
        }
        img
    }

    #[test]
    fn a_blurred_footprint_is_centred_where_its_sharp_image_is() {
        // Two spots of a defocused projector, each a disc of radius 3 blurred by σ = 6 (a
        // footprint about 30 pixels across), off the pixel grid, with a ripple of ±2% of the
        // peak standing in for noise and a uniform background of 5% (global light).
        let (w, h) = (120usize, 80usize);
        let centres = [(30.37, 41.81), (88.6, 30.25)];
        let mut img = vec![0.0f32; w * h];
        for c in centres {
            for (v, s) in img.iter_mut().zip(blurred_disc(w, h, c, 3.0, 6.0)) {
                *v += s;
            }
        }
        let peak = img.iter().copied().fold(0.0f32, f32::max);
        for (i, v) in img.iter_mut().enumerate() {
            let ripple = ((i * 7919 % 101) as f32 / 100.0 - 0.5) * 0.04 * peak;
            *v += 0.05 * peak + ripple;
        }
        let found = spots(&img, w, 0.15 * peak, 20).expect("spots");
        assert_eq!(found.len(), 2, "{found:?}");
        for (spot, (cx, cy)) in found.iter().zip([centres[1], centres[0]]) {
            let err = ((spot.centroid[0] - cx).powi(2) + (spot.centroid[1] - cy).powi(2)).sqrt();
            // Measured 0.0x px; the bar is ±1 px.
            assert!(err < 0.1, "{spot:?} against ({cx}, {cy}): {err:.3} px");
            assert!(spot.pixels > 200, "{spot:?}");
        }
        // A floor under the background merges everything into one region: the centroid is
        // then the light's mean, between the two (the floor matters, and it is the caller's).
        let merged = spots(&img, w, 0.01 * peak, 20).expect("spots");
        assert_eq!(merged.len(), 1, "{merged:?}");
    }

    #[test]
    fn a_local_floor_finds_a_dim_blurred_spot_beside_a_bright_sharp_one() {
        // A sharp spot (disc of radius 4, σ 1) and, 60 px away, one spread over a wide blur
        // (σ 8) whose core is 1% of the sharp one's peak.
        // Gaussian-like noise of σ 2e-4 of the sharp peak (a deterministic hash).
        let (w, h) = (140usize, 80usize);
        let (sharp, dim) = ((35.3, 40.6), (95.8, 38.2));
        let mut img = blurred_disc(w, h, sharp, 4.0, 1.0);
        let wide = blurred_disc(w, h, dim, 4.0, 8.0);
        let scale = 0.01 * img.iter().copied().fold(0.0f32, f32::max)
            / wide.iter().copied().fold(0.0f32, f32::max);
        for (v, s) in img.iter_mut().zip(wide) {
            *v += scale * s;
        }
        let peak = img.iter().copied().fold(0.0f32, f32::max);
        for (i, v) in img.iter_mut().enumerate() {
            let u =
                ((i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) as f32 / (1 << 24) as f32;
            let u2 = ((i as u64 + 7).wrapping_mul(0xC2B2_AE3D_27D4_EB4F) >> 40) as f32
                / (1 << 24) as f32;
            *v += 2e-4 * peak * (u + u2 - 1.0) * 2.45;
        }
        // One floor for the image at 5% of the peak: the dim spot is lost.
        let global = spots(&img, w, 0.05 * peak, 16).expect("spots");
        assert_eq!(global.len(), 1, "{global:?}");
        let sigma = noise_sigma(&img);
        assert!(
            sigma > 1e-4 * peak && sigma < 4e-4 * peak,
            "noise {sigma} against {peak}"
        );
        let floor = local_floor(&img, w, 25, 0.2, 8.0 * sigma).expect("floor");
        let found = spots_over(&img, w, &floor, 16).expect("spots");
        assert_eq!(found.len(), 2, "{found:?}");
        for (spot, (cx, cy)) in found.iter().zip([dim, sharp]) {
            let err = ((spot.centroid[0] - cx).powi(2) + (spot.centroid[1] - cy).powi(2)).sqrt();
            assert!(err < 0.3, "{spot:?} against ({cx}, {cy}): {err:.3} px");
        }
    }

    #[test]
    fn a_spot_split_by_an_edge_is_merged_back_to_its_centroid() {
        // A blurred disc cut in two by a dark gap two pixels wide through its centre (an edge),
        // and a second spot 60 px away that must stay apart.
        let (w, h) = (140usize, 60usize);
        let (cut, other) = ((40.0, 30.3), (100.4, 28.7));
        let mut img = blurred_disc(w, h, cut, 4.0, 2.5);
        for (v, s) in img.iter_mut().zip(blurred_disc(w, h, other, 4.0, 2.5)) {
            *v += s;
        }
        for y in 0..h {
            img[y * w + 39] = 0.0;
            img[y * w + 40] = 0.0;
        }
        let peak = img.iter().copied().fold(0.0f32, f32::max);
        let found = spots(&img, w, 0.05 * peak, 4).expect("spots");
        assert_eq!(found.len(), 3, "{found:?}");
        let merged = merge_spots(&found, 16.0);
        assert_eq!(merged.len(), 2, "{merged:?}");
        for (cx, cy) in [cut, other] {
            let err = merged
                .iter()
                .map(|s| ((s.centroid[0] - cx).powi(2) + (s.centroid[1] - cy).powi(2)).sqrt())
                .fold(f64::INFINITY, f64::min);
            assert!(err < 0.3, "{merged:?} against ({cx}, {cy}): {err:.3} px");
        }
        let total: f64 = found.iter().map(|s| s.light).sum();
        let kept: f64 = merged.iter().map(|s| s.light).sum();
        assert!(
            (total - kept).abs() < 1e-9 * total,
            "{total} against {kept}"
        );
        assert!(merge_spots(&[], 16.0).is_empty());
    }

    #[test]
    fn merged_spots_without_light_keep_the_first_centroid() {
        let dark = |x: f64| Spot {
            centroid: [x, 5.0],
            light: 0.0,
            pixels: 3,
        };
        let merged = merge_spots(&[dark(10.0), dark(12.0)], 4.0);
        assert_eq!(merged.len(), 1, "{merged:?}");
        assert_eq!(
            merged[0].centroid.map(f64::to_bits),
            [10.0f64, 5.0].map(f64::to_bits)
        );
        assert_eq!(merged[0].pixels, 6);
    }

    #[test]
    fn the_window_maximum_matches_a_direct_scan() {
        let values: Vec<f32> = (0..37u32).map(|i| ((i * 7919) % 23) as f32).collect();
        for r in [0usize, 1, 2, 5, 40] {
            let fast = window_max(&values, r);
            for (i, m) in fast.iter().enumerate() {
                let direct = values[i.saturating_sub(r)..(i + r + 1).min(values.len())]
                    .iter()
                    .copied()
                    .fold(f32::NEG_INFINITY, f32::max);
                assert_eq!(m.to_bits(), direct.to_bits(), "radius {r} at {i}");
            }
        }
        assert!(window_max(&[], 3).is_empty());
    }

    #[test]
    fn bad_input_is_refused() {
        assert!(local_floor(&[0.0; 4], 2, 1, 1.5, 0.0).is_err());
        assert!(local_floor(&[0.0; 4], 2, 1, 0.5, f32::NAN).is_err());
        assert!(local_floor(&[0.0; 4], 3, 1, 0.5, 0.0).is_err());
        assert!(spots_over(&[0.0; 4], 2, &[0.0; 3], 1).is_err());
        assert!(spots_over(&[0.0; 4], 2, &[0.0, 0.0, f32::INFINITY, 0.0], 1).is_err());
        assert!(spots(&[0.0; 10], 3, 0.1, 1).is_err());
        assert!(spots(&[0.0, f32::NAN, 0.0], 3, 0.1, 1).is_err());
        assert!(spots(&[0.0; 3], 3, f32::INFINITY, 1).is_err());
        assert!(spots(&[0.0; 3], 0, 0.1, 1).is_err());
        assert!(spots(&[], 3, 0.1, 1).expect("empty").is_empty());
    }

    #[test]
    fn block_centres_average_the_mapped_camera_pixels() {
        // A 4×2 camera seeing an 8×4 projector at twice the scale: camera (x, y) sees projector
        // pixel (2x, 2y). Blocks of 4: block 0 holds projector x 0..4, y 0..4.
        let map: Vec<Option<u32>> = (0..8u32)
            .map(|i| Some((i / 4) * 2 * 8 + (i % 4) * 2))
            .collect();
        let b = block_centres(&map, 4, (8, 4), 4);
        assert_eq!(b.len(), 2);
        assert_eq!(b[0], Some(([1.0, 1.0], 4)));
        assert_eq!(b[1], Some(([3.0, 1.0], 4)));
        let none = block_centres(&[None; 8], 4, (8, 4), 4);
        assert!(none.iter().all(Option::is_none));
    }
}
