//! Nodes (DESIGN §4.4): per luminaire projector, the charts it lights and one node per chart
//! region (nearest chart in projector coordinates), feathered across node boundaries and across
//! projector overlaps so that the weights on every surface point sum to one; luminaire pixels
//! that land on the target (its camera mask, dilated) are black.

use crate::CalibError;
use crate::charts::{COLUMNS, ChartCorners, Homography, ROWS};
use crate::graycode::Correspondence;
use std::collections::VecDeque;

/// How to split and feather.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeConfig {
    /// Width of the ramp between neighbouring nodes, in projector pixels.
    pub node_feather_px: f32,
    /// Width of the ramp at the boundary of a projector's footprint (frustum edge or shadow), in
    /// camera pixels: where projectors overlap, each one's share falls to zero towards it.
    pub edge_feather_px: f32,
    /// Margin around the target, in projector pixels, kept black by luminaires.
    pub target_margin_px: u32,
    /// Fewest decoded patch centres for a chart to count as lit by a projector.
    pub min_patches: usize,
}

impl Default for NodeConfig {
    fn default() -> Self {
        Self {
            node_feather_px: 40.0,
            edge_feather_px: 12.0,
            target_margin_px: 6,
            min_patches: 6,
        }
    }
}

/// One node: a chart's region of one projector, as linear-light weights in `[0, 1]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    /// Index of the projector (in the order the correspondences were given).
    pub projector: usize,
    /// Index of the chart whose region this is.
    pub chart: usize,
    /// The chart's position in projector pixels.
    pub anchor: (f32, f32),
    /// Weight of every projector pixel, row-major.
    pub weights: Vec<f32>,
}

/// The nodes of every luminaire, and each projector's pixels kept black for the target.
#[derive(Debug, Clone, PartialEq)]
pub struct Segmentation {
    /// All nodes, projector by projector.
    pub nodes: Vec<Node>,
    /// Per projector: pixels that light the target or its margin (black in every frame).
    pub excluded: Vec<Vec<bool>>,
}

/// Projector pixel → the camera pixel that sees it, filled outwards from decoded pixels so that
/// every projector pixel has one (nearest decoded neighbour in projector space, 4-connected).
fn inverse_map(c: &Correspondence) -> Vec<Option<u32>> {
    let (pw, ph) = (c.projector_width as usize, c.projector_height as usize);
    let mut inv: Vec<Option<u32>> = vec![None; pw * ph];
    let mut best = vec![f32::NEG_INFINITY; pw * ph];
    for (i, (m, conf)) in c.map.iter().zip(&c.confidence).enumerate() {
        if let Some((x, y)) = m {
            let k = *y as usize * pw + *x as usize;
            if *conf > best[k] {
                best[k] = *conf;
                inv[k] = Some(i as u32);
            }
        }
    }
    let mut queue: VecDeque<usize> = (0..pw * ph).filter(|&k| inv[k].is_some()).collect();
    while let Some(k) = queue.pop_front() {
        let (x, y) = (k % pw, k / pw);
        let around = [
            (x > 0).then(|| k - 1),
            (x + 1 < pw).then(|| k + 1),
            (y > 0).then(|| k - pw),
            (y + 1 < ph).then(|| k + pw),
        ];
        for n in around.into_iter().flatten() {
            if inv[n].is_none() {
                inv[n] = inv[k];
                queue.push_back(n);
            }
        }
    }
    inv
}

/// Distance (chamfer, in pixels) from every pixel inside `mask` to the nearest pixel outside it
/// or to the image border; 0 outside.
fn distance_inside(mask: &[bool], w: usize, h: usize) -> Vec<f32> {
    const D: f32 = std::f32::consts::SQRT_2;
    let mut d: Vec<f32> = mask
        .iter()
        .map(|&m| if m { f32::INFINITY } else { 0.0 })
        .collect();
    let at = |x: isize, y: isize, d: &[f32]| {
        if x < 0 || y < 0 || x >= w as isize || y >= h as isize {
            0.0
        } else {
            d[y as usize * w + x as usize]
        }
    };
    for y in 0..h as isize {
        for x in 0..w as isize {
            let k = y as usize * w + x as usize;
            if d[k] > 0.0 {
                let best = (at(x - 1, y, &d) + 1.0)
                    .min(at(x, y - 1, &d) + 1.0)
                    .min(at(x - 1, y - 1, &d) + D)
                    .min(at(x + 1, y - 1, &d) + D);
                d[k] = d[k].min(best);
            }
        }
    }
    for y in (0..h as isize).rev() {
        for x in (0..w as isize).rev() {
            let k = y as usize * w + x as usize;
            if d[k] > 0.0 {
                let best = (at(x + 1, y, &d) + 1.0)
                    .min(at(x, y + 1, &d) + 1.0)
                    .min(at(x + 1, y + 1, &d) + D)
                    .min(at(x - 1, y + 1, &d) + D);
                d[k] = d[k].min(best);
            }
        }
    }
    d
}

/// Erodes a mask by `r` pixels (square neighbourhood).
fn erode(mask: &[bool], w: usize, h: usize, r: u32) -> Vec<bool> {
    let inverted: Vec<bool> = mask.iter().map(|m| !m).collect();
    dilate(&inverted, w, h, r).into_iter().map(|m| !m).collect()
}

/// Splits every luminaire projector into nodes and feathers them.
///
/// `luminaires[k]` is projector k's decoded correspondence; `charts` are the chart corners in
/// the camera image; `target_mask` marks camera pixels on the projection-mapping target.
pub fn segment(
    luminaires: &[Correspondence],
    charts: &[ChartCorners],
    target_mask: Option<&[bool]>,
    config: &NodeConfig,
) -> Result<Segmentation, CalibError> {
    let Some(first) = luminaires.first() else {
        return Ok(Segmentation {
            nodes: Vec::new(),
            excluded: Vec::new(),
        });
    };
    let (cw, ch) = (first.width as usize, first.height as usize);
    for (k, c) in luminaires.iter().enumerate() {
        if c.width as usize != cw || c.height as usize != ch {
            return Err(CalibError::Invalid {
                field: "correspondences",
                problem: format!(
                    "projector {k}'s map is {}x{}, projector 0's {cw}x{ch}",
                    c.width, c.height
                ),
            });
        }
    }
    if let Some(mask) = target_mask
        && mask.len() != cw * ch
    {
        return Err(CalibError::Invalid {
            field: "target mask",
            problem: format!("{} pixels, expected {cw}x{ch}", mask.len()),
        });
    }
    // Patch centres of every chart in camera pixels.
    let centres: Vec<Vec<usize>> = charts
        .iter()
        .map(|chart| {
            let hom =
                Homography::from_corners(&chart.corners).ok_or_else(|| CalibError::Invalid {
                    field: "chart corners",
                    problem: format!("chart {}: not a quadrilateral", chart.name),
                })?;
            Ok((0..COLUMNS * ROWS)
                .filter_map(|k| {
                    let [u, v] = hom.apply((k % COLUMNS) as f64 + 0.5, (k / COLUMNS) as f64 + 0.5);
                    (u >= 0.0 && v >= 0.0 && (u as usize) < cw && (v as usize) < ch)
                        .then(|| v as usize * cw + u as usize)
                })
                .collect())
        })
        .collect::<Result<_, CalibError>>()?;
    // Overlap shares in camera space: each projector's share at a surface point ramps from 0 at
    // the boundary of its footprint (frustum edge or shadow) to 1 at `edge_feather_px` camera
    // pixels inside it; the shares of the projectors at a point are normalised to sum to 1.
    // The footprint is the decoded region with small gaps (unknown pixels) closed.
    let shares: Vec<Vec<f32>> = luminaires
        .iter()
        .map(|c| {
            let covered: Vec<bool> = c.map.iter().map(Option::is_some).collect();
            let closed = erode(&dilate(&covered, cw, ch, 2), cw, ch, 2);
            distance_inside(&closed, cw, ch)
                .into_iter()
                .map(|d| (d / config.edge_feather_px.max(1e-3)).min(1.0))
                .collect()
        })
        .collect();
    let total: Vec<f32> = (0..cw * ch)
        .map(|i| shares.iter().map(|s| s[i]).sum())
        .collect();
    let mut nodes = Vec::new();
    let mut excluded = Vec::with_capacity(luminaires.len());
    for (k, c) in luminaires.iter().enumerate() {
        let (pw, ph) = (c.projector_width as usize, c.projector_height as usize);
        let anchors: Vec<(usize, (f32, f32))> = centres
            .iter()
            .enumerate()
            .filter_map(|(m, pts)| {
                let hits: Vec<(u32, u32)> = pts.iter().filter_map(|&i| c.map[i]).collect();
                (hits.len() >= config.min_patches).then(|| {
                    let n = hits.len() as f32;
                    (
                        m,
                        (
                            hits.iter().map(|h| h.0 as f32).sum::<f32>() / n,
                            hits.iter().map(|h| h.1 as f32).sum::<f32>() / n,
                        ),
                    )
                })
            })
            .collect();
        if anchors.is_empty() {
            return Err(CalibError::Invalid {
                field: "projectors",
                problem: format!(
                    "luminaire projector {k} lights no chart (fewer than {} patch centres decoded on every chart)",
                    config.min_patches
                ),
            });
        }
        let inv = inverse_map(c);
        // Blend share of each projector pixel: its share at the surface point it lights over the
        // sum of all shares there; 1 where no projector's footprint has a share (unseen).
        let blend: Vec<f32> = (0..pw * ph)
            .map(|p| match inv[p] {
                Some(i) if total[i as usize] > 0.0 => shares[k][i as usize] / total[i as usize],
                _ => 1.0,
            })
            .collect();
        // Target exclusion: projector pixels that light target pixels, dilated by the margin.
        let mut black = vec![false; pw * ph];
        if let Some(mask) = target_mask {
            for (i, m) in c.map.iter().enumerate() {
                if let (true, Some((x, y))) = (mask[i], m) {
                    black[*y as usize * pw + *x as usize] = true;
                }
            }
            for p in 0..pw * ph {
                if let Some(i) = inv[p] {
                    black[p] |= mask[i as usize];
                }
            }
            black = dilate(&black, pw, ph, config.target_margin_px);
        }
        // Node weights: piecewise-linear partition of unity over the distance to each anchor.
        let mut weights = vec![vec![0.0f32; pw * ph]; anchors.len()];
        let band = config.node_feather_px.max(1e-3);
        let mut raw = vec![0.0f32; anchors.len()];
        for p in 0..pw * ph {
            if black[p] {
                continue;
            }
            let (x, y) = ((p % pw) as f32 + 0.5, (p / pw) as f32 + 0.5);
            let d: Vec<f32> = anchors
                .iter()
                .map(|(_, (ax, ay))| ((x - ax).powi(2) + (y - ay).powi(2)).sqrt())
                .collect();
            let dmin = d.iter().copied().fold(f32::INFINITY, f32::min);
            let mut sum = 0.0;
            for (r, dn) in raw.iter_mut().zip(&d) {
                *r = (1.0 - (dn - dmin) / band).max(0.0);
                sum += *r;
            }
            // sum ≥ 1: the nearest anchor always contributes 1.
            for (w, r) in weights.iter_mut().zip(&raw) {
                w[p] = blend[p] * r / sum;
            }
        }
        for ((chart, anchor), w) in anchors.into_iter().zip(weights) {
            nodes.push(Node {
                projector: k,
                chart,
                anchor,
                weights: w,
            });
        }
        excluded.push(black);
    }
    Ok(Segmentation { nodes, excluded })
}

/// Dilates a mask by `r` pixels (square neighbourhood), separably.
pub fn dilate(mask: &[bool], w: usize, h: usize, r: u32) -> Vec<bool> {
    let r = r as usize;
    if r == 0 {
        return mask.to_vec();
    }
    let mut rows = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            if mask[y * w + x] {
                for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                    rows[y * w + xx] = true;
                }
            }
        }
    }
    let mut out = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            if rows[y * w + x] {
                for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                    out[yy * w + x] = true;
                }
            }
        }
    }
    out
}

/// Projector pixels kept dark around the target for a whole-frame node (large aperture, or a
/// projector that lights no chart), as a share of the frame's width: a large aperture's light
/// blurs away from the focus plane, and pixels the decode missed are dark only through this.
const WHOLE_FRAME_TARGET_MARGIN: f64 = 0.06;

/// A projector as one node (a large aperture, or a luminaire that lights no chart): weights 1
/// over its whole frame except the pixels that land on the target (decoded, then dilated by a
/// margin of 6% of the frame's width); its chart for the conventional start is the one it
/// lights over the most camera pixels, if any.
pub fn whole_frame(
    corr: &Correspondence,
    corners: &[ChartCorners],
    target: &[bool],
) -> (Vec<f32>, Option<usize>) {
    let (w, h) = (corr.projector_width, corr.projector_height);
    let mut dark = vec![false; (w * h) as usize];
    for (m, &t) in corr.map.iter().zip(target) {
        if let (Some((x, y)), true) = (m, t)
            && *x < w
            && *y < h
        {
            dark[(y * w + x) as usize] = true;
        }
    }
    let margin = (WHOLE_FRAME_TARGET_MARGIN * f64::from(w)).ceil() as u32;
    let dark = dilate(&dark, w as usize, h as usize, margin);
    let weights: Vec<f32> = dark.iter().map(|&d| if d { 0.0 } else { 1.0 }).collect();
    // The chart with the most camera pixels this projector was decoded on.
    let width = corr.width as usize;
    let mut counts = vec![0usize; corners.len()];
    for (i, m) in corr.map.iter().enumerate() {
        if m.is_none() {
            continue;
        }
        let (x, y) = ((i % width) as f64 + 0.5, (i / width) as f64 + 0.5);
        if let Some(c) = corners.iter().position(|c| inside(&c.corners, x, y)) {
            counts[c] += 1;
        }
    }
    let chart = (0..corners.len())
        .max_by_key(|&c| counts[c])
        .filter(|&c| counts[c] > 0);
    (weights, chart)
}

/// Whether `(x, y)` lies inside the convex quadrilateral `q`.
fn inside(q: &[[f64; 2]; 4], x: f64, y: f64) -> bool {
    let side = |a: [f64; 2], b: [f64; 2]| (b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0]);
    let s: Vec<f64> = (0..4).map(|i| side(q[i], q[(i + 1) % 4])).collect();
    s.iter().all(|&v| v >= 0.0) || s.iter().all(|&v| v <= 0.0)
}
