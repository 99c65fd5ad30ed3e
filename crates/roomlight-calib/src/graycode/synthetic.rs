//! Synthetic structured-light captures for unit tests: projectors each lighting a rectangle of
//! a small camera, with reflected light, an ambient level, noise and clipping, so that decoding
//! paths can be compared bit for bit without the simulator.

use super::{Manifest, Pattern};
use crate::image_io::LinearImage;

/// A projector of a synthetic room: its manifest and the camera rectangle `(x0, y0, x1, y1)`
/// (exclusive ends) its frame covers.
pub(crate) struct Lit<'a> {
    pub manifest: &'a Manifest,
    pub area: (u32, u32, u32, u32),
}

/// Uniform in `[-1, 1)` from a seed and two indices (splitmix64).
fn noise(seed: u64, a: u64, b: u64) -> f32 {
    let mut z =
        seed ^ a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 40) as f32 / (1u64 << 23) as f32 - 1.0
}

/// The `w × h` capture (number `shot`, which seeds its noise) of `lit[k]` showing `shown[k]`
/// (`None`: black): direct light rising left to right so that white clips at the right, a
/// reflected share of each projector's mean over its rectangle, an ambient level, noise, and
/// the ceiling at 1 per channel.
pub(crate) fn capture(
    (w, h): (u32, u32),
    lit: &[Lit<'_>],
    shown: &[Option<Pattern>],
    shot: u64,
) -> LinearImage {
    let gains = [0.9f32, 1.0, 0.7];
    let mut light = vec![0.02f32; (w * h) as usize];
    for (p, pattern) in lit.iter().zip(shown) {
        let Some(pattern) = *pattern else { continue };
        let values = p.manifest.pattern_values(pattern);
        let mean = values.iter().sum::<f32>() / values.len().max(1) as f32;
        let (x0, y0, x1, y1) = p.area;
        let (pw, ph) = (p.manifest.width, p.manifest.height);
        for y in y0..y1 {
            for x in x0..x1 {
                let (u, v) = ((x - x0) * pw / (x1 - x0), (y - y0) * ph / (y1 - y0));
                let direct = 0.3 + 0.9 * x as f32 / w as f32;
                light[(y * w + x) as usize] += direct * values[(v * pw + u) as usize] + 0.15 * mean;
            }
        }
    }
    LinearImage {
        width: w,
        height: h,
        pixels: light
            .iter()
            .enumerate()
            .map(|(i, l)| {
                std::array::from_fn(|c| {
                    let n = 0.004 * noise(0x5EED, shot, (3 * i + c) as u64);
                    (gains[c] * l + n).clamp(0.0, 1.0)
                })
            })
            .collect(),
    }
}
