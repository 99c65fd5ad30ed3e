//! The whole room, not just the charts (issue 22, item 1): per camera pixel, CIEDE2000 between
//! the room under the LEDs and under the projectors' result; why the pixels no projector lights
//! cannot be lit; and how much worse the colour is along the edges where projectors overlap.
//!
//! Everything here is ground truth from the simulator: noiseless renders in the room camera's
//! view and each luminaire's direct light per camera pixel. The metric definitions:
//! - **Lab white**: both images are converted with one white, the 99th percentile of the LED
//!   reference's luminance over the pixels that see a surface (L* = 100 there); camera RGB is
//!   taken as linear sRGB, D65, as on the charts ([`roomlight_core::metrics::lab_from_linear_rgb`]).
//! - **Reached**: a luminaire projector lights the pixel's surface directly through a projector
//!   pixel some node drives. The mean and 95th percentile (nearest rank) are over reached pixels.
//! - **Seam**: a reached pixel is on a seam when a 4-neighbour is reached by a different set of
//!   projectors (the edge of a footprint inside another's); the seam band is every reached pixel
//!   within [`SEAM_BAND_PX`] (Chebyshev distance) of one. The seam metric is the band's mean
//!   ΔE00 minus the mean over the other reached pixels (positive: the overlaps show).

use anyhow::{Context, Result, bail, ensure};
use image::{Rgb, RgbImage};
use roomlight_core::LinearRgb;
use roomlight_core::metrics::{ciede2000, lab_from_linear_rgb, luminance};
use roomlight_sim::geometry::V3;
use roomlight_sim::scene::ProjectorRole;
use roomlight_sim::{Capture, NodeRegion, Room};

/// Half-width, in camera pixels, of the band along projector-overlap edges.
pub const SEAM_BAND_PX: usize = 4;

/// ΔE00 at the top of the maps' colour bar (larger values take its top colour).
pub const MAP_MAX_DE00: f64 = 20.0;

/// Why a camera pixel can or cannot be lit by the luminaire projectors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reach {
    /// The camera pixel sees no surface (outside the fisheye's circle): not counted anywhere.
    NoSurface,
    /// A luminaire lights it directly through a projector pixel that some node drives.
    Reached,
    /// A luminaire lights it directly, but only through projector pixels no node drives
    /// (calibration left them out: the target, beyond the nodes).
    NoNode,
    /// Inside some luminaire's image, but hidden from it (in a shadow, or facing away).
    Occluded,
    /// Outside every luminaire's image.
    Outside,
}

/// Per camera pixel: whether the luminaires can light it, and which do.
#[derive(Debug, Clone)]
pub struct ReachMap {
    pub width: usize,
    pub height: usize,
    pub reach: Vec<Reach>,
    /// Bit `k`: projector `k` of the room lights the pixel through a node (reached pixels only).
    pub lit_by: Vec<u64>,
}

/// The room's luminaire projectors, as indices into its projectors.
pub fn luminaires(room: &Room) -> Vec<usize> {
    room.scene()
        .projectors
        .iter()
        .enumerate()
        .filter(|(_, p)| p.role == ProjectorRole::Luminaire)
        .map(|(k, _)| k)
        .collect()
}

impl ReachMap {
    /// From the simulator's truth: each luminaire's direct light per camera pixel, the projector
    /// pixel through its lens centre, and the node `regions` (which projector pixels are driven).
    pub fn new(room: &Room, regions: &[NodeRegion]) -> Result<Self> {
        let projectors = room.projectors();
        ensure!(
            projectors.len() <= 64,
            "whole-room reach: {} projectors, at most 64 are supported",
            projectors.len()
        );
        let luminaires = luminaires(room);
        // Per projector, the pixels some node drives (weight above zero).
        let mut driven: Vec<Vec<bool>> = projectors
            .iter()
            .map(|p| vec![false; (p.pinhole.width * p.pinhole.height) as usize])
            .collect();
        for r in regions {
            let d = driven
                .get_mut(r.projector)
                .with_context(|| format!("a node region names projector {}", r.projector))?;
            ensure!(
                r.weights.len() == d.len(),
                "a node region of projector {} has {} weights for {} pixels",
                r.projector,
                r.weights.len(),
                d.len()
            );
            for (dst, w) in d.iter_mut().zip(&r.weights) {
                *dst |= *w > 0.0;
            }
        }
        let factors: Vec<&[f32]> = luminaires.iter().map(|&k| room.direct_factor(k)).collect();
        let pixels = room.pixels();
        let mut reach = Vec::with_capacity(pixels.len());
        let mut lit_by = Vec::with_capacity(pixels.len());
        for (i, info) in pixels.iter().enumerate() {
            let Some(point) = info.point else {
                reach.push(Reach::NoSurface);
                lit_by.push(0);
                continue;
            };
            let point = V3::from_array(point);
            let (mut bits, mut lit, mut in_image) = (0u64, false, false);
            for (&k, factor) in luminaires.iter().zip(&factors) {
                let pinhole = &projectors[k].pinhole;
                let uv = pinhole.project(point);
                in_image |= uv.and_then(|uv| pinhole.pixel(uv)).is_some();
                if factor.get(i).is_some_and(|f| *f > 0.0) {
                    lit = true;
                    // The projector pixel through the lens centre; a large aperture's blur
                    // lights a little beyond its image's edge, from the edge's pixels.
                    let edge = |v: f32, n: u32| v.clamp(0.0, n as f32 - 0.5);
                    let px = uv.and_then(|(u, v)| {
                        pinhole.pixel((edge(u, pinhole.width), edge(v, pinhole.height)))
                    });
                    if px.is_some_and(|j| driven[k][j as usize]) {
                        bits |= 1 << k;
                    }
                }
            }
            reach.push(if bits != 0 {
                Reach::Reached
            } else if lit {
                Reach::NoNode
            } else if in_image {
                Reach::Occluded
            } else {
                Reach::Outside
            });
            lit_by.push(bits);
        }
        let camera = &room.scene().camera;
        Ok(Self {
            width: camera.resolution[0] as usize,
            height: camera.resolution[1] as usize,
            reach,
            lit_by,
        })
    }

    /// Shares of the pixels that see a surface: (reached, no node, occluded, outside); all zero
    /// when no pixel sees a surface.
    pub fn shares(&self) -> [f64; 4] {
        let classes = [
            Reach::Reached,
            Reach::NoNode,
            Reach::Occluded,
            Reach::Outside,
        ];
        let counts = classes.map(|c| self.reach.iter().filter(|r| **r == c).count());
        let surface: usize = counts.iter().sum();
        // No surface in view: every share is zero rather than 0/0.
        counts.map(|n| {
            if surface > 0 {
                n as f64 / surface as f64
            } else {
                0.0
            }
        })
    }

    /// The seam band: reached pixels within `band` pixels of an edge where the set of projectors
    /// that light them changes.
    pub fn seam_band(&self, band: usize) -> Vec<bool> {
        let (w, h) = (self.width, self.height);
        let reached = |i: usize| self.reach[i] == Reach::Reached;
        let mut edge = vec![false; w * h];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if !reached(i) {
                    continue;
                }
                let differs = |j: usize| reached(j) && self.lit_by[j] != self.lit_by[i];
                if (x + 1 < w && differs(i + 1)) || (y + 1 < h && differs(i + w)) {
                    edge[i] = true;
                    // The neighbour is on the same edge.
                    if x + 1 < w && differs(i + 1) {
                        edge[i + 1] = true;
                    }
                    if y + 1 < h && differs(i + w) {
                        edge[i + w] = true;
                    }
                }
            }
        }
        // A square dilation, rows then columns.
        let mut rows = vec![false; w * h];
        for y in 0..h {
            for x in 0..w {
                let (a, b) = (x.saturating_sub(band), (x + band).min(w - 1));
                rows[y * w + x] = (a..=b).any(|xx| edge[y * w + xx]);
            }
        }
        let mut out = vec![false; w * h];
        for y in 0..h {
            for x in 0..w {
                let (a, b) = (y.saturating_sub(band), (y + band).min(h - 1));
                out[y * w + x] = reached(y * w + x) && (a..=b).any(|yy| rows[yy * w + x]);
            }
        }
        out
    }
}

/// The Lab white: the 99th percentile (nearest rank) of `reference`'s luminance over the pixels
/// where `mask` holds. An error when none does or the reference is black there.
pub fn white_luminance(reference: &Capture, mask: &[bool]) -> Result<f64> {
    ensure!(
        mask.len() == reference.pixels.len(),
        "white: {} mask entries for {} pixels",
        mask.len(),
        reference.pixels.len()
    );
    let mut l: Vec<f64> = reference
        .pixels
        .iter()
        .zip(mask)
        .filter(|(_, m)| **m)
        .map(|(p, _)| luminance(rgb(p)))
        .collect();
    let white = nearest_rank(&mut l, 0.99)
        .context("white: no pixel of the LED reference sees a surface")?;
    if !(white.is_finite() && white > 0.0) {
        bail!("white: the LED reference's 99th percentile luminance is {white}, expected > 0");
    }
    Ok(white)
}

fn rgb(p: &[f32; 3]) -> LinearRgb {
    LinearRgb(p.map(|v| f64::from(v).max(0.0)))
}

/// The `q` quantile by nearest rank (the smallest value with at least `q·n` values at or
/// below it); none for no values. Sorts `v`.
pub fn nearest_rank(v: &mut [f64], q: f64) -> Option<f64> {
    v.sort_by(f64::total_cmp);
    let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len().max(1));
    v.get(rank - 1).copied()
}

/// ΔE00 per pixel between `reference` and `result` (both linear camera RGB of the same size),
/// with `white` as L* = 100. Errors on a size mismatch or a value that is not finite.
pub fn delta_e_map(reference: &Capture, result: &Capture, white: f64) -> Result<Vec<f64>> {
    ensure!(
        (reference.width, reference.height) == (result.width, result.height)
            && reference.pixels.len() == result.pixels.len(),
        "ΔE00 map: the result is {}×{}, the reference {}×{}",
        result.width,
        result.height,
        reference.width,
        reference.height
    );
    ensure!(
        white > 0.0,
        "ΔE00 map: white luminance {white}, expected > 0"
    );
    reference
        .pixels
        .iter()
        .zip(&result.pixels)
        .enumerate()
        .map(|(i, (a, b))| {
            if a.iter().chain(b).any(|v| !v.is_finite()) {
                bail!("ΔE00 map: pixel {i} is not finite ({a:?} against {b:?})");
            }
            Ok(ciede2000(
                lab_from_linear_rgb(rgb(a), white),
                lab_from_linear_rgb(rgb(b), white),
            ))
        })
        .collect()
}

/// ΔE00 along the projector-overlap edges against elsewhere.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Seam {
    /// Half-width of the band, camera pixels.
    pub band_px: usize,
    /// Share of the reached pixels in the band.
    pub band_share: f64,
    /// Mean ΔE00 in the band and over the other reached pixels.
    pub band_de00_mean: f64,
    pub elsewhere_de00_mean: f64,
    /// The band's mean minus elsewhere's: the seam metric.
    pub excess_de00: f64,
}

/// The whole-room figures of one preset.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct WholeRoom {
    /// Luminance taken as L* = 100 (the LED reference's 99th percentile).
    pub white_luminance: f64,
    /// Mean and 95th percentile of ΔE00 over the reached pixels.
    pub de00_mean: f64,
    pub de00_p95: f64,
    /// Pixels that see a surface, and the shares of them reached, lit only through undriven
    /// projector pixels, occluded, outside every luminaire's image.
    pub surface_pixels: usize,
    pub reached_share: f64,
    pub no_node_share: f64,
    pub occluded_share: f64,
    pub outside_share: f64,
    /// None when no two reached neighbours differ in their projectors (a single footprint), or
    /// when the band or the rest is empty.
    pub seam: Option<Seam>,
}

impl WholeRoom {
    /// The figures from a ΔE00 map and the reach map it belongs to.
    pub fn measure(de00: &[f64], reach: &ReachMap, white_luminance: f64) -> Result<Self> {
        ensure!(
            de00.len() == reach.reach.len(),
            "whole room: {} ΔE00 values for {} pixels",
            de00.len(),
            reach.reach.len()
        );
        let reached = |i: &usize| reach.reach[*i] == Reach::Reached;
        let mut values: Vec<f64> = (0..de00.len()).filter(reached).map(|i| de00[i]).collect();
        ensure!(
            !values.is_empty(),
            "whole room: no camera pixel is lit by a luminaire through a node"
        );
        let de00_mean = values.iter().sum::<f64>() / values.len() as f64;
        let de00_p95 = nearest_rank(&mut values, 0.95).unwrap_or(0.0);
        let band = reach.seam_band(SEAM_BAND_PX);
        let mean_of = |inside: bool| {
            let v: Vec<f64> = (0..de00.len())
                .filter(|i| reached(i) && band[*i] == inside)
                .map(|i| de00[i])
                .collect();
            (!v.is_empty()).then(|| (v.iter().sum::<f64>() / v.len() as f64, v.len()))
        };
        let seam = match (mean_of(true), mean_of(false)) {
            (Some((b, nb)), Some((e, ne))) => Some(Seam {
                band_px: SEAM_BAND_PX,
                band_share: nb as f64 / (nb + ne) as f64,
                band_de00_mean: b,
                elsewhere_de00_mean: e,
                excess_de00: b - e,
            }),
            _ => None,
        };
        let [reached_share, no_node_share, occluded_share, outside_share] = reach.shares();
        Ok(Self {
            white_luminance,
            de00_mean,
            de00_p95,
            surface_pixels: reach
                .reach
                .iter()
                .filter(|r| **r != Reach::NoSurface)
                .count(),
            reached_share,
            no_node_share,
            occluded_share,
            outside_share,
            seam,
        })
    }
}

/// Colours of the pixels no luminaire reaches, with their legend labels (the font has capitals,
/// digits and a little punctuation only).
const CLASS_COLOURS: [(Reach, [u8; 3], &str); 4] = [
    (Reach::NoNode, [225, 225, 225], "NO NODE"),
    (Reach::Occluded, [150, 150, 150], "OCCLUDED"),
    (Reach::Outside, [95, 95, 95], "OUTSIDE"),
    (Reach::NoSurface, [0, 0, 0], "NO SURFACE"),
];

/// Viridis at five stops, interpolated linearly: `t` in `[0, 1]`.
fn viridis(t: f64) -> [u8; 3] {
    const STOPS: [[f64; 3]; 5] = [
        [68.0, 1.0, 84.0],
        [59.0, 82.0, 139.0],
        [33.0, 145.0, 140.0],
        [94.0, 201.0, 98.0],
        [253.0, 231.0, 37.0],
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        1.0
    };
    let s = t * 4.0;
    let k = (s.floor() as usize).min(3);
    let f = s - k as f64;
    std::array::from_fn(|c| (STOPS[k][c] + f * (STOPS[k + 1][c] - STOPS[k][c])).round() as u8)
}

/// Width of the colour bar's panel beside the map.
const PANEL: u32 = 170;

/// The ΔE00 map (0 to [`MAP_MAX_DE00`], viridis) with the unreached pixels in greys, and a
/// panel on the right with the colour bar, its ticks and the greys' legend.
pub fn map_image(de00: &[f64], reach: &ReachMap) -> Result<RgbImage> {
    let (w, h) = (reach.width as u32, reach.height as u32);
    ensure!(
        de00.len() == reach.reach.len() && de00.len() == (w * h) as usize,
        "ΔE00 map image: {} values for {w}×{h} pixels",
        de00.len()
    );
    let mut img = RgbImage::from_pixel(w + PANEL, h.max(200), Rgb([255, 255, 255]));
    for (i, (d, r)) in de00.iter().zip(&reach.reach).enumerate() {
        let colour = match r {
            Reach::Reached => viridis(d / MAP_MAX_DE00),
            other => CLASS_COLOURS
                .iter()
                .find(|c| c.0 == *other)
                .map_or([255, 0, 255], |c| c.1),
        };
        img.put_pixel(i as u32 % w, i as u32 / w, Rgb(colour));
    }
    draw_panel(&mut img, w + 8, h.max(200));
    Ok(img)
}

/// The colour bar (top = [`MAP_MAX_DE00`] and above), ticks every 5, and the legend below.
fn draw_panel(img: &mut RgbImage, x0: u32, height: u32) {
    let black = Rgb([0, 0, 0]);
    let text = |img: &mut RgbImage, s: &str, x: u32, y: u32| {
        roomlight_hw::font::draw(s, x, y, 2, |px, py| {
            if px < img.width() && py < img.height() {
                img.put_pixel(px, py, black);
            }
        });
    };
    text(img, "DE00", x0, 4);
    let (top, bar_h, bar_w) = (32, (height * 55 / 100).max(60), 18);
    for y in 0..bar_h {
        let t = 1.0 - f64::from(y) / f64::from(bar_h - 1);
        for x in 0..bar_w {
            img.put_pixel(x0 + x, top + y, Rgb(viridis(t)));
        }
    }
    let ticks = (MAP_MAX_DE00 / 5.0).round() as u32;
    for k in 0..=ticks {
        let y = top + (bar_h - 1) - (bar_h - 1) * k / ticks.max(1);
        for x in bar_w..bar_w + 5 {
            img.put_pixel(x0 + x, y, black);
        }
        let label = if k == ticks {
            format!("{}+", k * 5)
        } else {
            format!("{}", k * 5)
        };
        text(img, &label, x0 + bar_w + 8, y.saturating_sub(7));
    }
    let mut y = top + bar_h + 12;
    for (_, colour, label) in CLASS_COLOURS {
        if y + 14 > img.height() {
            break;
        }
        for dy in 0..14 {
            for dx in 0..14 {
                let edge = dx == 0 || dy == 0 || dx == 13 || dy == 13;
                img.put_pixel(x0 + dx, y + dy, if edge { black } else { Rgb(colour) });
            }
        }
        text(img, label, x0 + 20, y);
        y += 20;
    }
}

/// The `cw`×`ch` window (stepped by a quarter of its size) with the largest sum of reached pixels' ΔE00:
/// where the room looks worst. `(x, y, w, h)`, clipped to the image.
pub fn worst_window(de00: &[f64], reach: &ReachMap, cw: usize, ch: usize) -> (u32, u32, u32, u32) {
    let (w, h) = (reach.width, reach.height);
    let (cw, ch) = (cw.min(w), ch.min(h));
    // Summed-area table of ΔE00 over reached pixels, (w+1)×(h+1).
    let mut sat = vec![0.0f64; (w + 1) * (h + 1)];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let v = if reach.reach.get(i) == Some(&Reach::Reached) {
                de00.get(i).copied().unwrap_or(0.0)
            } else {
                0.0
            };
            sat[(y + 1) * (w + 1) + x + 1] =
                v + sat[y * (w + 1) + x + 1] + sat[(y + 1) * (w + 1) + x] - sat[y * (w + 1) + x];
        }
    }
    let sum = |x: usize, y: usize| {
        let at = |xx: usize, yy: usize| sat[yy * (w + 1) + xx];
        at(x + cw, y + ch) - at(x, y + ch) - at(x + cw, y) + at(x, y)
    };
    let mut best = (0, 0, f64::NEG_INFINITY);
    for y in (0..=h - ch).step_by((ch / 4).max(1)) {
        for x in (0..=w - cw).step_by((cw / 4).max(1)) {
            let s = sum(x, y);
            if s > best.2 {
                best = (x, y, s);
            }
        }
    }
    (best.0 as u32, best.1 as u32, cw as u32, ch as u32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use roomlight_core::metrics::patch_delta_e;

    fn capture(pixels: Vec<[f32; 3]>, width: u32) -> Capture {
        let height = pixels.len() as u32 / width;
        Capture {
            width,
            height,
            pixels,
        }
    }

    fn ramp() -> Vec<[f32; 3]> {
        (0..64)
            .map(|i| {
                let v = 0.05 + i as f32 / 70.0;
                [v, 0.8 * v, 0.6 * v + 0.01]
            })
            .collect()
    }

    #[test]
    fn identical_images_differ_by_zero() {
        let a = capture(ramp(), 8);
        let map = delta_e_map(&a, &a, 0.9).expect("map");
        assert_eq!(map.len(), 64);
        assert!(map.iter().all(|d| d.abs() < 1e-9), "{map:?}");
    }

    #[test]
    fn a_known_shift_matches_the_core_patch_metric() {
        // A 10% red gain on every pixel: the per-pixel map equals core's patch ΔE00 with the
        // same white (the brightest reference patch there; here the map takes it explicitly).
        let a = ramp();
        let b: Vec<[f32; 3]> = a.iter().map(|p| [p[0] * 1.1, p[1], p[2]]).collect();
        let to_rgb = |v: &[[f32; 3]]| v.iter().map(rgb).collect::<Vec<_>>();
        let core = patch_delta_e(&to_rgb(&a), &to_rgb(&b)).expect("core ΔE00");
        let white = a.iter().map(|p| luminance(rgb(p))).fold(0.0, f64::max);
        let map = delta_e_map(&capture(a, 8), &capture(b, 8), white).expect("map");
        for (m, c) in map.iter().zip(&core.per_patch) {
            assert!((m - c).abs() < 1e-4, "{m} against {c}");
        }
        let mean = map.iter().sum::<f64>() / map.len() as f64;
        assert!((mean - core.mean).abs() < 1e-4);
        assert!(core.mean > 1.0, "the shift is visible: {}", core.mean);
    }

    #[test]
    fn bad_input_is_an_error() {
        let a = capture(ramp(), 8);
        let b = capture(ramp(), 4);
        assert!(delta_e_map(&a, &b, 1.0).is_err());
        let mut c = a.clone();
        c.pixels[3][1] = f32::NAN;
        assert!(delta_e_map(&a, &c, 1.0).is_err());
        assert!(delta_e_map(&a, &a, 0.0).is_err());
        let black = capture(vec![[0.0; 3]; 64], 8);
        assert!(white_luminance(&black, &[true; 64]).is_err());
        assert!(white_luminance(&a, &[false; 64]).is_err());
    }

    #[test]
    fn nearest_rank_quantiles() {
        let mut v: Vec<f64> = (1..=100).rev().map(f64::from).collect();
        assert_eq!(nearest_rank(&mut v, 0.95), Some(95.0));
        assert_eq!(nearest_rank(&mut v, 0.99), Some(99.0));
        assert_eq!(nearest_rank(&mut [], 0.5), None);
    }

    /// A 20×10 room: projector 0 lights x < 12, projector 1 x ≥ 8 (overlap 8..12); the last
    /// row is occluded, one pixel sees nothing.
    fn two_footprints() -> ReachMap {
        let (w, h) = (20, 10);
        let mut reach = vec![Reach::Reached; w * h];
        let mut lit_by = vec![0u64; w * h];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                lit_by[i] = u64::from(x < 12) | (u64::from(x >= 8) << 1);
                if y == h - 1 {
                    reach[i] = Reach::Occluded;
                    lit_by[i] = 0;
                }
            }
        }
        reach[0] = Reach::NoSurface;
        lit_by[0] = 0;
        ReachMap {
            width: w,
            height: h,
            reach,
            lit_by,
        }
    }

    #[test]
    fn seam_band_follows_the_overlap_edges() {
        let map = two_footprints();
        let band = map.seam_band(1);
        // Edges between x = 7|8 and x = 11|12; band of 1 pixel: x in 6..=13 on reached rows.
        for y in 0..9 {
            for x in 0..20 {
                let want = (6..=13).contains(&x) && !(x == 0 && y == 0);
                assert_eq!(band[y * 20 + x], want, "({x}, {y})");
            }
        }
        assert!(!band[9 * 20 + 8], "occluded pixels are never in the band");
        let shares = map.shares();
        assert!((shares[0] - 179.0 / 199.0).abs() < 1e-12);
        assert!((shares[2] - 20.0 / 199.0).abs() < 1e-12);
        assert!((shares.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn the_seam_metric_is_band_minus_elsewhere() {
        let map = two_footprints();
        let band = map.seam_band(SEAM_BAND_PX);
        let de: Vec<f64> = band.iter().map(|b| if *b { 6.0 } else { 2.0 }).collect();
        let w = WholeRoom::measure(&de, &map, 1.0).expect("measure");
        let seam = w.seam.expect("two footprints overlap");
        assert!((seam.band_de00_mean - 6.0).abs() < 1e-12);
        assert!((seam.elsewhere_de00_mean - 2.0).abs() < 1e-12);
        assert!((seam.excess_de00 - 4.0).abs() < 1e-12);
        assert_eq!(w.surface_pixels, 199);
        // 53 pixels at 2 then 126 at 6: the 171st of 179 is 6.
        assert!((w.de00_p95 - 6.0).abs() < 1e-12);
        assert!(w.de00_mean > 2.0 && w.de00_mean < 6.0);
    }

    #[test]
    fn the_map_image_has_a_colour_bar_and_the_worst_window_is_found() {
        let map = two_footprints();
        let mut de = vec![1.0; 200];
        de[5 * 20 + 17] = 40.0;
        let img = map_image(&de, &map).expect("image");
        assert_eq!(img.width(), 20 + PANEL);
        assert_eq!(img.get_pixel(17, 5).0, viridis(1.0));
        assert_eq!(img.get_pixel(0, 0).0, [0, 0, 0]);
        assert_eq!(img.get_pixel(3, 9).0, [150, 150, 150]);
        assert_eq!(viridis(0.0), [68, 1, 84]);
        assert_eq!(viridis(f64::NAN), [253, 231, 37]);
        let (x, y, cw, ch) = worst_window(&de, &map, 8, 4);
        assert_eq!((cw, ch), (8, 4));
        assert!((x..x + cw).contains(&17) && (y..y + ch).contains(&5));
    }

    /// The small scene without inter-reflection (so a render shows direct light only), every
    /// luminaire's whole image one node except the right half of the first luminaire's.
    #[test]
    fn reach_on_the_small_scene_matches_the_renders() {
        let mut scene = roomlight_sim::scenes::small().expect("small scene");
        scene.room.interreflection = false;
        let room = Room::build(scene).expect("room");
        let luminaires = luminaires(&room);
        let first = luminaires[0];
        let regions: Vec<NodeRegion> = luminaires
            .iter()
            .map(|&k| {
                let p = &room.projectors()[k].pinhole;
                let weights = (0..p.width * p.height)
                    .map(|j| {
                        if k == first && j % p.width >= p.width / 2 {
                            0.0
                        } else {
                            1.0
                        }
                    })
                    .collect();
                NodeRegion {
                    projector: k,
                    weights,
                }
            })
            .collect();
        let map = ReachMap::new(&room, &regions).expect("reach");
        // Each luminaire alone at white against all black: where its direct light lands.
        let black = vec![roomlight_sim::Frame::Black; room.projectors().len()];
        let dark = room.render(&black, None).expect("render");
        let lit: Vec<Vec<bool>> = luminaires
            .iter()
            .map(|&k| {
                let mut frames = black.clone();
                frames[k] = roomlight_sim::Frame::Uniform([1.0; 3]);
                let c = room.render(&frames, None).expect("render");
                c.pixels
                    .iter()
                    .zip(&dark.pixels)
                    .map(|(a, b)| a.iter().zip(b).any(|(x, y)| x - y > 1e-7))
                    .collect()
            })
            .collect();
        let surface: Vec<usize> = (0..map.reach.len())
            .filter(|&i| room.pixels()[i].point.is_some())
            .collect();
        let unlit = surface
            .iter()
            .filter(|&&i| lit.iter().all(|l| !l[i]))
            .count();
        let shares = map.shares();
        let unreachable = shares[2] + shares[3];
        let expected = unlit as f64 / surface.len() as f64;
        assert!(
            (unreachable - expected).abs() < 2e-3,
            "unreachable {unreachable} against {expected} from the renders"
        );
        assert!(expected > 0.01 && expected < 0.9, "{expected}");
        // Lit only by the first luminaire's undriven half: no node.
        let only_first = surface
            .iter()
            .filter(|&&i| lit[0][i] && lit[1..].iter().all(|l| !l[i]))
            .count();
        assert!(shares[1] > 0.0 && shares[1] * surface.len() as f64 <= only_first as f64 + 1.0);
        assert!((shares.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert_eq!(
            surface.len(),
            map.reach.iter().filter(|r| **r != Reach::NoSurface).count()
        );
    }
}
