//! Nodes (DESIGN §4.4): per luminaire projector, the charts it lights and one node per chart
//! region (nearest chart in projector coordinates), feathered across node boundaries and across
//! projector overlaps so that the weights on every surface point sum to one; luminaire pixels
//! that land on the target (its camera mask, dilated) are black.

use crate::CalibError;
use crate::charts::{COLUMNS, ChartCorners, Homography, ROWS};
use crate::graycode::Correspondence;
use std::collections::VecDeque;

mod between;
mod bridge;
mod mask;
mod whole;

pub use mask::dilate;
use mask::{distance_inside, erode};
pub use whole::whole_frame;

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
    /// Radius, in camera pixels, of the closing (dilation then erosion) that fills gaps of
    /// unknown pixels inside a decoded footprint before its edges are ramped
    /// ([`overlap_shares`]). A gap left open is an edge: the projector's share ramps down
    /// around it and the others' up, so a decode speckled with unknown pixels (a noisier one,
    /// such as groups coded in their primaries) gives speckled weights, and chart patches
    /// the attenuation captures then see as non-uniform are dropped from the model. At 2,
    /// the lab's model kept 212 of its chart patches on neutral coded in white and 182 in
    /// primaries (charts' mean ΔE00 2.07 and 2.58); at 5, 215 and 214 (2.06 and 2.20), the
    /// whole room's 95th percentile lower on every preset (`roomlight demo [--white]`,
    /// 2026-12-07). A shadow narrower than twice this is lit as if it were not there.
    pub gap_close_px: u32,
    /// How far inside its footprint's edge (camera pixels) a projector's share stays 0 before
    /// it ramps up over [`Self::edge_feather_px`]: where another projector gives light, this
    /// rim of it stays dark (a projector whose footprint no other reaches lights its rim in
    /// full). Its edge is where a decode is least sure (a camera pixel half on the footprint,
    /// a stripe too dim to read, a pixel a row off), and a ramp that starts there turns each
    /// such pixel into weights that miss one by a ramp step. Measured on 2026-12-07 (`roomlight
    /// bench calib`, overlaps within 1e-3 / 0.05): the lab's bring-up 97.09 / 98.96% at 0,
    /// about 97.35 / 99.23% at 1.5 and 97.87 / 99.45% at 8; but at 1.5 the small room's
    /// (`--quick`) fell from 96.03 / 98.69% to 95.72 / 98.29% and its charts' ΔE00 in `bench
    /// room --quick` from 1.38 to 1.72, and at 8 the lab's whole-room 95th percentile rose by
    /// 1.5–3.4 ΔE00 on four of five presets (`roomlight demo`). So 0 by default.
    pub edge_inset_px: f32,
}

impl Default for NodeConfig {
    fn default() -> Self {
        Self {
            node_feather_px: 40.0,
            edge_feather_px: 12.0,
            target_margin_px: 6,
            min_patches: 6,
            gap_close_px: 5,
            edge_inset_px: 0.0,
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
    /// Per projector, per camera pixel: the share of the light at that surface point that the
    /// projector's nodes give together, in `[0, 1]` (0 outside its footprint). A projector
    /// segmented later beside these keeps to what they leave ([`segment_beside`]).
    pub claims: Vec<Vec<f32>>,
}

/// Projector pixel → the camera pixel that sees it: the most confident decoded one; else a
/// bridged one (`map` is `c`'s map with its gaps bridged, `bridged` marks those,
/// [`bridge::bridged`]); else filled outwards from those so that every projector pixel has one
/// (nearest neighbour in projector space, 4-connected). The second value is each pixel's
/// number of steps from the decoded or bridged one it took its camera pixel from (0: its own).
fn inverse_map(
    c: &Correspondence,
    map: &[Option<(u32, u32)>],
    bridged: &[bool],
) -> (Vec<Option<u32>>, Vec<u32>) {
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
    for (i, m) in map.iter().enumerate() {
        if let (true, Some((x, y))) = (bridged[i], m) {
            let k = *y as usize * pw + *x as usize;
            if inv[k].is_none() {
                inv[k] = Some(i as u32);
            }
        }
    }
    let mut hops = vec![0u32; pw * ph];
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
                hops[n] = hops[k] + 1;
                queue.push_back(n);
            }
        }
    }
    (inv, hops)
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
    segment_beside(luminaires, charts, target_mask, config, None)
}

/// [`segment`] beside projectors that keep their weights: `claimed[i]` is the share of the
/// light at camera pixel `i` they already give (the sum of their [`Segmentation::claims`]).
/// The new projectors share what is left, `1 − claimed`, feathered among themselves as
/// [`segment`] does, so that the weights of old and new sum to one wherever a new one
/// reaches. A projector that joins a lit room is segmented this way: the others' weights, and
/// so their measured attenuation, stay as they are. Where an old projector's footprint ends
/// inside a new one's, the new one's share steps up as the old one's steps down (the old
/// weights cannot be feathered without measuring them again). Claims outside `[0, 1]` or not
/// finite are refused, naming the pixel.
pub fn segment_beside(
    luminaires: &[Correspondence],
    charts: &[ChartCorners],
    target_mask: Option<&[bool]>,
    config: &NodeConfig,
    claimed: Option<&[f32]>,
) -> Result<Segmentation, CalibError> {
    let Some(first) = luminaires.first() else {
        return Ok(Segmentation {
            nodes: Vec::new(),
            excluded: Vec::new(),
            claims: Vec::new(),
        });
    };
    let (cw, ch) = (first.width as usize, first.height as usize);
    check_sizes(luminaires, target_mask, claimed, (cw, ch))?;
    let centres = patch_centres(charts, cw, ch)?;
    // The charts each projector lights, checked before any blending work.
    let lit = lit_charts(luminaires, &centres, config)?;
    let shares = overlap_shares(luminaires, (cw, ch), config);
    let per = blend_in_order(luminaires, &shares, target_mask, claimed, config);
    let mut nodes = Vec::new();
    let mut excluded = Vec::with_capacity(luminaires.len());
    let mut claims = Vec::with_capacity(luminaires.len());
    for (k, ((c, done), anchors)) in luminaires.iter().zip(per).zip(lit).enumerate() {
        let Some(Blended {
            blend,
            black,
            claim,
        }) = done
        else {
            continue;
        };
        let weights = node_weights(c, &anchors, &blend, &black, config);
        for ((chart, anchor), w) in anchors.into_iter().zip(weights) {
            nodes.push(Node {
                projector: k,
                chart,
                anchor,
                weights: w,
            });
        }
        claims.push(claim);
        excluded.push(black);
    }
    Ok(Segmentation {
        nodes,
        excluded,
        claims,
    })
}

/// Every map, the target mask and the claimed shares have the camera's size `(cw, ch)`, and
/// every claim is a share in `[0, 1]`.
fn check_sizes(
    luminaires: &[Correspondence],
    target_mask: Option<&[bool]>,
    claimed: Option<&[f32]>,
    (cw, ch): (usize, usize),
) -> Result<(), CalibError> {
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
    if let Some(claimed) = claimed {
        if claimed.len() != cw * ch {
            return Err(CalibError::Invalid {
                field: "claimed shares",
                problem: format!("{} pixels, expected {cw}x{ch}", claimed.len()),
            });
        }
        if let Some(i) = claimed.iter().position(|c| !(0.0..=1.0).contains(c)) {
            return Err(CalibError::Invalid {
                field: "claimed shares",
                problem: format!(
                    "{} at camera pixel ({}, {}); expected a share in [0, 1]",
                    claimed[i],
                    i % cw,
                    i / cw
                ),
            });
        }
    }
    Ok(())
}

/// A chart a projector lights and the node's anchor on it (projector pixels).
type Anchor = (usize, (f32, f32));

/// Per projector, the charts it lights and its anchor on each; a projector that lights none is
/// refused.
fn lit_charts(
    luminaires: &[Correspondence],
    centres: &[Vec<usize>],
    config: &NodeConfig,
) -> Result<Vec<Vec<Anchor>>, CalibError> {
    luminaires
        .iter()
        .enumerate()
        .map(|(k, c)| {
            let a = anchors(c, centres, config);
            if a.is_empty() {
                return Err(CalibError::Invalid {
                    field: "projectors",
                    problem: format!(
                        "luminaire projector {k} lights no chart (fewer than {} patch centres decoded on every chart)",
                        config.min_patches
                    ),
                });
            }
            Ok(a)
        })
        .collect()
}

/// Overlap shares in camera space: each projector's share at a surface point ramps from 0 at
/// the boundary of its footprint (frustum edge or shadow) to 1 at `edge_feather_px` camera
/// pixels inside it; the shares of the projectors at a point are normalised to sum to 1.
/// The footprint is the decoded region with small gaps (unknown pixels) closed
/// ([`NodeConfig::gap_close_px`]).
fn overlap_shares(
    luminaires: &[Correspondence],
    (cw, ch): (usize, usize),
    config: &NodeConfig,
) -> Vec<Vec<f32>> {
    luminaires
        .iter()
        .map(|c| {
            let covered: Vec<bool> = c.map.iter().map(Option::is_some).collect();
            let r = config.gap_close_px;
            let closed = erode(&dilate(&covered, cw, ch, r), cw, ch, r);
            let inset = config.edge_inset_px.max(0.0);
            distance_inside(&closed, cw, ch)
                .into_iter()
                .map(|d| ((d - inset).max(0.0) / config.edge_feather_px.max(1e-3)).min(1.0))
                .collect()
        })
        .collect()
}

/// The projectors take their blend one after the other, coarsest first: each takes its
/// share of what the ones before it left (their actual light at each camera pixel, pixel
/// steps and all), in proportion to its share among itself and those still to come. The
/// last at a surface point takes exactly what is left there, so its finer pixel grid
/// absorbs the staircase of the coarser ones' ramps instead of adding its own.
///
/// Returns, per projector, its blend per projector pixel, its pixels kept black and its claims.
fn blend_in_order(
    luminaires: &[Correspondence],
    shares: &[Vec<f32>],
    target_mask: Option<&[bool]>,
    claimed: Option<&[f32]>,
    config: &NodeConfig,
) -> Vec<Option<Blended>> {
    let Some(first) = luminaires.first() else {
        return Vec::new();
    };
    let (cw, ch) = (first.width as usize, first.height as usize);
    let mut order: Vec<usize> = (0..luminaires.len()).collect();
    let fineness: Vec<f64> = luminaires
        .iter()
        .map(projector_pixels_per_camera_pixel)
        .collect();
    order.sort_by(|a, b| fineness[*a].total_cmp(&fineness[*b]).then(a.cmp(b)));
    let mut taken: Vec<f32> = claimed.map_or_else(|| vec![0.0; cw * ch], <[f32]>::to_vec);
    let mut per: Vec<Option<Blended>> = vec![None; luminaires.len()];
    for (rank, &k) in order.iter().enumerate() {
        let c = &luminaires[k];
        let (pw, ph) = (c.projector_width as usize, c.projector_height as usize);
        let rest = &order[rank..];
        // Its blend at a camera pixel: what is left there times its share over the shares of
        // itself and the projectors after it; 0 where none of them reaches (shares sum to 0).
        let blend_at = |i: usize| {
            let remaining: f32 = rest.iter().map(|&j| shares[j][i]).sum();
            let free = (1.0 - taken[i]).max(0.0);
            if remaining > 0.0 {
                free * shares[k][i] / remaining
            } else {
                0.0
            }
        };
        let (map, bridged) = bridge::bridged(c);
        let (inv, hops) = inverse_map(c, &map, &bridged);
        let read_between = between::between(&inv, &hops, (pw, ph), cw);
        // On the outermost ring of its footprint (where its share, ramping up from its inset,
        // is below a pixel and a half's worth) or outside it.
        let inset = config.edge_inset_px.max(0.0);
        let rim = |i: usize| shares[k][i] * config.edge_feather_px.max(1e-3) + inset < 1.5;
        // Projector pixels a camera pixel spans on either side of the one decoded at its
        // centre: half the map's step, at least 1.
        let beyond = (bridge::step(c) / 2.0).ceil().max(1.0) as u32;
        // Where another projector gives light at a camera pixel: one segmented with it has a
        // share there, or one segmented before it claimed some.
        let others_reach = |i: usize| {
            claimed.is_some_and(|c| c[i] > 0.0)
                || (0..shares.len()).any(|j| j != k && shares[j][i] > 0.0)
        };
        // Blend of each projector pixel: at the surface point it lights (all that is left
        // there where no footprint has a share: unseen).
        let blend: Vec<f32> = (0..pw * ph)
            .map(|p| match inv[p] {
                // Filled more than one step from a pixel with a camera pixel of its own, and
                // landing (read between those on either side, [`between`]) outside its own
                // footprint where another gives light: a band it grazes, too dim to decode,
                // which the others, seeing no footprint of it there, light in full. One step
                // is the pixel beside a decoded one, which still lights that camera pixel where
                // the projector is finer than the camera.
                Some(_)
                    if hops[p] > 1
                        && read_between[p].is_some_and(|j| {
                            shares[k][j as usize] == 0.0 && others_reach(j as usize)
                        }) =>
                {
                    0.0
                }
                // Filled from the outermost ring of its footprint (chamfer distance 1 or √2
                // from its edge, beyond its inset), further from what was decoded than a camera
                // pixel spans: beyond the footprint's decoded edge (a grazing strip the decode
                // missed), where the others, seeing no footprint of this projector, give all
                // their light. Nearer, the pixel still lights that camera pixel where the
                // projector is finer than the camera (the lab's bring-up, overlaps within 1e-3:
                // 97.09% beyond half the map's step, 96.74% beyond one step, 2026-12-07).
                Some(i) if hops[p] > beyond && rim(i as usize) && others_reach(i as usize) => 0.0,
                Some(i) if shares[k][i as usize] > 0.0 => blend_at(i as usize),
                // Its footprint's inset rim, or filled from it: the others give all there.
                Some(i) if others_reach(i as usize) => 0.0,
                Some(i) => (1.0 - taken[i as usize]).max(0.0),
                None => 1.0,
            })
            .collect();
        let black = target_black(c, &inv, target_mask, config.target_margin_px);
        // The light it gives each camera pixel: the blend of the projector pixel decoded (or
        // bridged) there (0 where it is kept black); in its footprint's other gaps, the
        // camera-space blend.
        let claim: Vec<f32> = (0..cw * ch)
            .map(|i| match map[i] {
                Some((x, y)) => {
                    let p = y as usize * pw + x as usize;
                    if p < pw * ph && !black[p] {
                        blend[p]
                    } else {
                        0.0
                    }
                }
                None => blend_at(i),
            })
            .collect();
        add_claim(&mut taken, &claim);
        per[k] = Some(Blended {
            blend,
            black,
            claim,
        });
    }
    per
}

/// Target exclusion: the projector pixels that light target pixels (decoded there, or the
/// inverse map's pick), dilated by `margin` pixels; none without a target mask.
fn target_black(
    c: &Correspondence,
    inv: &[Option<u32>],
    target_mask: Option<&[bool]>,
    margin: u32,
) -> Vec<bool> {
    let (pw, ph) = (c.projector_width as usize, c.projector_height as usize);
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
        black = dilate(&black, pw, ph, margin);
    }
    black
}

/// Node weights of one projector: a piecewise-linear partition of unity over the distance to
/// each anchor, times the overlap blend; zero where the projector is kept black.
fn node_weights(
    c: &Correspondence,
    anchors: &[Anchor],
    blend: &[f32],
    black: &[bool],
    config: &NodeConfig,
) -> Vec<Vec<f32>> {
    let (pw, ph) = (c.projector_width as usize, c.projector_height as usize);
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
    weights
}

/// Adds a projector's claims (see [`Segmentation::claims`]) to the shares already claimed at
/// each camera pixel, capped at 1 (what [`segment_beside`] takes as `claimed`).
pub fn add_claim(claimed: &mut [f32], claim: &[f32]) {
    for (t, c) in claimed.iter_mut().zip(claim) {
        *t = (*t + c).min(1.0);
    }
}

/// One projector's overlap blend (per projector pixel), its pixels kept black for the target,
/// and the light it gives each camera pixel.
#[derive(Debug, Clone)]
struct Blended {
    blend: Vec<f32>,
    black: Vec<bool>,
    claim: Vec<f32>,
}

/// How many projector pixels a camera pixel sees, over the decoded region: distinct projector
/// pixels decoded over camera pixels decoded (0 where nothing is decoded).
fn projector_pixels_per_camera_pixel(c: &Correspondence) -> f64 {
    let pw = c.projector_width as usize;
    let mut seen = vec![false; pw * c.projector_height as usize];
    let mut decoded = 0usize;
    for (x, y) in c.map.iter().flatten() {
        decoded += 1;
        if let Some(s) = seen.get_mut(*y as usize * pw + *x as usize) {
            *s = true;
        }
    }
    // Nothing decoded: 0 (the projector goes first; it claims nothing anyway).
    if decoded == 0 {
        return 0.0;
    }
    seen.iter().filter(|s| **s).count() as f64 / decoded as f64
}

/// Patch centres of every chart, as camera pixel indices (those inside a `cw`×`ch` image).
fn patch_centres(
    charts: &[ChartCorners],
    cw: usize,
    ch: usize,
) -> Result<Vec<Vec<usize>>, CalibError> {
    charts
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
        .collect()
}

/// The charts a projector lights (at least `min_patches` patch centres decoded) and each one's
/// position in projector pixels (the mean of its decoded patch centres).
fn anchors(
    c: &Correspondence,
    centres: &[Vec<usize>],
    config: &NodeConfig,
) -> Vec<(usize, (f32, f32))> {
    centres
        .iter()
        .enumerate()
        .filter_map(|(m, pts)| {
            let hits: Vec<(u32, u32)> = pts
                .iter()
                .filter_map(|&i| c.map.get(i).copied().flatten())
                .collect();
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
        .collect()
}

/// The charts a projector lights, by index into `charts` (see [`segment`]: a projector that
/// lights none cannot be split by charts). Corners that are not a quadrilateral are refused.
pub fn charts_lit(
    c: &Correspondence,
    charts: &[ChartCorners],
    config: &NodeConfig,
) -> Result<Vec<usize>, CalibError> {
    let centres = patch_centres(charts, c.width as usize, c.height as usize)?;
    Ok(anchors(c, &centres, config)
        .into_iter()
        .map(|(m, _)| m)
        .collect())
}

/// How well luminaires' weights sum to one on the surface points the camera sees, measured
/// through a correspondence the caller trusts (the simulator's truth, in tests and benches).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Partition {
    /// Camera pixels checked.
    pub points: usize,
    /// Of those, the ones two or more projectors reach.
    pub overlap: usize,
    /// Share of the points whose weights sum to one within 1e-3, and within 0.05.
    pub within_1e3: f64,
    pub within_0_05: f64,
    /// The same shares over the overlap points alone (issue 21's bar: ≥ 99% within 1e-3,
    /// ≥ 99.5% within 0.05); both 0 without overlaps.
    pub overlap_within_1e3: f64,
    pub overlap_within_0_05: f64,
    /// The largest miss where one projector reaches, and where several do.
    pub worst_single: f32,
    pub worst_overlap: f32,
}

impl std::fmt::Display for Partition {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} surface points: {:.2}% within 1e-3, {:.2}% within 0.05; {} in overlaps: {:.2}% within 1e-3, {:.2}% within 0.05; worst {:.3} where one projector reaches, {:.3} in overlaps",
            self.points,
            100.0 * self.within_1e3,
            100.0 * self.within_0_05,
            self.overlap,
            100.0 * self.overlap_within_1e3,
            100.0 * self.overlap_within_0_05,
            self.worst_single,
            self.worst_overlap
        )
    }
}

/// The sum of projector weights at every camera pixel not `skip`ped: `truth[k][i]` is the
/// pixel of projector `k` that lights camera pixel `i`'s surface point, `weights[k]` the sum of
/// its nodes' weights per projector pixel, `dark[k]` its pixels kept black (a point lit through
/// one is not checked: behind the target's silhouette it stays dark). Pixel indices outside a
/// projector's weights count as weight 0.
pub fn partition_of_unity(
    truth: &[Vec<Option<u32>>],
    weights: &[Vec<f32>],
    dark: &[Vec<bool>],
    skip: &[bool],
) -> Partition {
    let mut out = Partition {
        points: 0,
        overlap: 0,
        within_1e3: 0.0,
        within_0_05: 0.0,
        overlap_within_1e3: 0.0,
        overlap_within_0_05: 0.0,
        worst_single: 0.0,
        worst_overlap: 0.0,
    };
    let (mut tight, mut loose) = (0usize, 0usize);
    let (mut overlap_tight, mut overlap_loose) = (0usize, 0usize);
    for (i, &skipped) in skip.iter().enumerate() {
        let reaching: Vec<(usize, usize)> = truth
            .iter()
            .enumerate()
            .filter_map(|(k, t)| t.get(i).copied().flatten().map(|p| (k, p as usize)))
            .collect();
        let through_dark = reaching
            .iter()
            .any(|&(k, p)| dark.get(k).and_then(|d| d.get(p)).copied().unwrap_or(false));
        if skipped || reaching.is_empty() || through_dark {
            continue;
        }
        let sum: f32 = reaching
            .iter()
            .map(|&(k, p)| {
                weights
                    .get(k)
                    .and_then(|w| w.get(p))
                    .copied()
                    .unwrap_or(0.0)
            })
            .sum();
        let miss = (sum - 1.0).abs();
        tight += usize::from(miss <= 1e-3);
        loose += usize::from(miss <= 0.05);
        if reaching.len() == 1 {
            out.worst_single = out.worst_single.max(miss);
        } else {
            out.overlap += 1;
            overlap_tight += usize::from(miss <= 1e-3);
            overlap_loose += usize::from(miss <= 0.05);
            out.worst_overlap = out.worst_overlap.max(miss);
        }
        out.points += 1;
    }
    // No point checked: both shares 0.
    out.within_1e3 = tight as f64 / out.points.max(1) as f64;
    out.within_0_05 = loose as f64 / out.points.max(1) as f64;
    out.overlap_within_1e3 = overlap_tight as f64 / out.overlap.max(1) as f64;
    out.overlap_within_0_05 = overlap_loose as f64 / out.overlap.max(1) as f64;
    out
}

/// Every node weight of projector `k` summed per projector pixel (empty if it has no node).
pub fn projector_weights(nodes: &[Node], k: usize) -> Vec<f32> {
    let mut sum: Vec<f32> = Vec::new();
    for n in nodes.iter().filter(|n| n.projector == k) {
        sum.resize(sum.len().max(n.weights.len()), 0.0);
        for (s, w) in sum.iter_mut().zip(&n.weights) {
            *s += w;
        }
    }
    sum
}
