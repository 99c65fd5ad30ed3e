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
    if width == 0 || !light.len().is_multiple_of(width) {
        return Err(CalibError::Invalid {
            field: "spot image",
            problem: format!("{} pixels do not make rows of {width}", light.len()),
        });
    }
    if !floor.is_finite() {
        return Err(CalibError::Invalid {
            field: "spot floor",
            problem: format!("{floor} is not finite"),
        });
    }
    if let Some(i) = light.iter().position(|v| !v.is_finite()) {
        return Err(CalibError::Invalid {
            field: "spot image",
            problem: format!("light {} at pixel ({}, {})", light[i], i % width, i / width),
        });
    }
    let height = light.len() / width;
    let mut seen = vec![false; light.len()];
    let mut out = Vec::new();
    let mut queue = VecDeque::new();
    for start in 0..light.len() {
        if seen[start] || light[start] <= floor {
            continue;
        }
        seen[start] = true;
        queue.push_back(start);
        let (mut sum, mut sx, mut sy, mut n) = (0.0f64, 0.0f64, 0.0f64, 0usize);
        while let Some(i) = queue.pop_front() {
            let (x, y) = (i % width, i / width);
            let w = f64::from(light[i] - floor);
            sum += w;
            sx += w * (x as f64 + 0.5);
            sy += w * (y as f64 + 0.5);
            n += 1;
            for ny in y.saturating_sub(1)..(y + 2).min(height) {
                for nx in x.saturating_sub(1)..(x + 2).min(width) {
                    let j = ny * width + nx;
                    if !seen[j] && light[j] > floor {
                        seen[j] = true;
                        queue.push_back(j);
                    }
                }
            }
        }
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
    fn bad_input_is_refused() {
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
