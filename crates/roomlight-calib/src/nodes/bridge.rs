//! Gaps of a decoded map bridged for blending (issue 21, item 7): a camera pixel the decoder
//! left unknown inside a projector's footprint (a row of pixels whose direct light is too weak
//! to decide a bit, a stripe edge) still lies on a surface point the projector lights. The
//! blend is worked out per camera pixel, and each projector pixel takes the blend of the camera
//! pixel that sees it ([`super::inverse_map`]); a projector pixel whose own camera pixel is
//! unknown took its nearest decoded neighbour's, one camera row away, where the coarser
//! projectors' ramps have moved on by a step, so the weights at that surface point missed one
//! by that step. Bridging puts such a pixel back where its decoded neighbours on both sides
//! say it lies.
//!
//! This is for blending only: the decoded correspondence itself keeps the pixel unknown (a
//! guess must never pass for a decoded pixel), and a bridged pixel never displaces a decoded
//! one in the inverse map. Hand-written: it is a few lines of linear interpolation on the
//! decoder's own map, which no image crate does with the consistency check below.

use crate::graycode::Correspondence;

/// How far (camera pixels) a decoded neighbour may be, on each side of an unknown pixel.
pub(super) const BRIDGE_RADIUS: usize = 3;

/// The most projector pixels the two sides may differ by per camera pixel between them, on
/// top of the map's own step ([`step`]): more is a depth edge or a shadow's border, where the
/// pixel between lies on neither side's surface.
const BRIDGE_SLACK: f64 = 2.0;

/// The share of neighbouring decoded pixels whose projector pixels are at most [`step`]
/// apart.
const STEP_SHARE: f64 = 0.9;

/// How far apart (projector pixels, the larger of the two axes) the projector pixels of two
/// neighbouring decoded camera pixels are, at the [`STEP_SHARE`] quantile over every such pair
/// in a row or a column (0 with no pair): the projector's scale in the camera, with grazing
/// surfaces in, and depth edges, the rare large jumps, out.
pub(super) fn step(c: &Correspondence) -> f64 {
    let (w, h) = (c.width as usize, c.height as usize);
    // Steps of 255 or more are counted as 255: a depth edge, never the quantile.
    let mut counts = [0usize; 256];
    let mut add = |a: Option<(u32, u32)>, b: Option<(u32, u32)>| {
        if let (Some(a), Some(b)) = (a, b) {
            let d = a.0.abs_diff(b.0).max(a.1.abs_diff(b.1)).min(255);
            counts[d as usize] += 1;
        }
    };
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if x + 1 < w {
                add(c.map[i], c.map[i + 1]);
            }
            if y + 1 < h {
                add(c.map[i], c.map[i + w]);
            }
        }
    }
    let total: usize = counts.iter().sum();
    let mut below = 0usize;
    for (d, n) in counts.iter().enumerate() {
        below += n;
        if below as f64 >= STEP_SHARE * total as f64 && total > 0 {
            return d as f64;
        }
    }
    0.0
}

/// `c`'s map with its gaps bridged: every unknown camera pixel that has decoded neighbours on
/// both sides of it along a row or a column, within [`BRIDGE_RADIUS`], whose projector pixels
/// agree with one surface (they differ by at most the map's [`step`] plus [`BRIDGE_SLACK`] per
/// camera pixel between them), gets the projector pixel interpolated
/// between them (the mean of the row's and the column's where both bridge it). The second
/// value marks the bridged pixels. Decoded pixels are returned as they are; only decoded
/// pixels are read, so a bridged pixel never bridges another.
pub(super) fn bridged(c: &Correspondence) -> (Vec<Option<(u32, u32)>>, Vec<bool>) {
    let (w, h) = (c.width as usize, c.height as usize);
    let mut map = c.map.clone();
    let mut marked = vec![false; map.len()];
    if map.len() != w * h {
        // A map of another size than it says: nothing to bridge (segment checks sizes first).
        return (map, marked);
    }
    let limit = step(c) + BRIDGE_SLACK;
    let at = |x: usize, y: usize| c.map[y * w + x];
    for y in 0..h {
        for x in 0..w {
            if at(x, y).is_some() {
                continue;
            }
            // Nearest decoded pixel at 1..=BRIDGE_RADIUS steps in one direction.
            let along = |dx: isize, dy: isize| {
                (1..=BRIDGE_RADIUS).find_map(|d| {
                    let nx = x as isize + dx * d as isize;
                    let ny = y as isize + dy * d as isize;
                    if nx < 0 || ny < 0 || nx >= w as isize || ny >= h as isize {
                        return None;
                    }
                    at(nx as usize, ny as usize).map(|p| (d, p))
                })
            };
            let estimates: Vec<[f64; 2]> = [((-1, 0), (1, 0)), ((0, -1), (0, 1))]
                .into_iter()
                .filter_map(|((ax, ay), (bx, by))| {
                    let ((da, pa), (db, pb)) = (along(ax, ay)?, along(bx, by)?);
                    let span = (da + db) as f64;
                    let (pa, pb) = (
                        [f64::from(pa.0), f64::from(pa.1)],
                        [f64::from(pb.0), f64::from(pb.1)],
                    );
                    let apart = (pb[0] - pa[0]).abs().max((pb[1] - pa[1]).abs());
                    // span ≥ 2: the pixel has a neighbour on each side.
                    (apart <= limit * span).then(|| {
                        let t = da as f64 / span;
                        [pa[0] + t * (pb[0] - pa[0]), pa[1] + t * (pb[1] - pa[1])]
                    })
                })
                .collect();
            if estimates.is_empty() {
                continue;
            }
            let n = estimates.len() as f64;
            let (ex, ey) = (
                estimates.iter().map(|e| e[0]).sum::<f64>() / n,
                estimates.iter().map(|e| e[1]).sum::<f64>() / n,
            );
            // Between two pixels of the projector: inside it, so the rounded value is too.
            let (px, py) = (ex.round() as u32, ey.round() as u32);
            if px < c.projector_width && py < c.projector_height {
                map[y * w + x] = Some((px, py));
                marked[y * w + x] = true;
            }
        }
    }
    (map, marked)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `w`×`h` camera seeing a projector of twice its size, 2 projector pixels per camera
    /// pixel along each axis, with `unknown` camera pixels left undecoded.
    fn map(w: u32, h: u32, unknown: impl Fn(u32, u32) -> bool) -> Correspondence {
        let n = (w * h) as usize;
        Correspondence {
            width: w,
            height: h,
            projector_width: 2 * w,
            projector_height: 2 * h,
            map: (0..n as u32)
                .map(|i| {
                    let (x, y) = (i % w, i / w);
                    (!unknown(x, y)).then_some((2 * x, 2 * y))
                })
                .collect(),
            confidence: vec![1.0; n],
            direct: vec![1.0; n],
            global: vec![0.0; n],
            reach: 0.1,
        }
    }

    #[test]
    fn a_row_of_unknown_pixels_is_bridged_at_its_true_projector_pixels() {
        let c = map(20, 12, |_, y| y == 5);
        let (bridged, marked) = bridged(&c);
        for x in 0..20 {
            let i = 5 * 20 + x as usize;
            assert!(marked[i], "({x}, 5) not bridged");
            assert_eq!(bridged[i], Some((2 * x, 10)), "({x}, 5)");
        }
        // Decoded pixels are untouched and unmarked.
        assert_eq!(marked.iter().filter(|m| **m).count(), 20);
        for (i, m) in c.map.iter().enumerate() {
            if m.is_some() {
                assert_eq!(bridged[i], *m);
            }
        }
    }

    #[test]
    fn a_gap_wider_than_the_radius_or_open_on_one_side_stays_unknown() {
        // A pixel is bridged when decoded pixels lie within the radius on both sides: a gap of
        // `radius` rows is bridged throughout, a gap of 2·radius rows nowhere. The image's
        // top-left 2×2 corner is unknown too: decoded only to its right and below.
        let r = BRIDGE_RADIUS as u32;
        for (rows, bridges) in [(r, true), (2 * r, false)] {
            let c = map(16, 20, |x, y| {
                (3..3 + rows).contains(&y) || (x < 2 && y < 2)
            });
            let (bridged, marked) = bridged(&c);
            for y in 3..3 + rows {
                let i = y as usize * 16 + 8;
                assert_eq!(marked[i], bridges, "row {y} of a gap of {rows}");
                assert_eq!(bridged[i].is_some(), bridges, "row {y} of a gap of {rows}");
            }
            for i in [0, 1, 16, 17] {
                assert_eq!(bridged[i], None, "corner pixel {i}");
            }
        }
        // The middle row of a gap of 2·radius − 1 rows, halfway between rows 2 and 2·radius + 2.
        let c = map(16, 20, |_, y| (3..2 + 2 * r).contains(&y));
        assert_eq!(
            bridged(&c).0[(2 + r) as usize * 16 + 8],
            Some((16, 2 * (2 + r)))
        );
    }

    #[test]
    fn a_depth_edge_is_not_bridged() {
        // Left of column 10 one surface, right of it another whose projector pixels jump by 60;
        // column 10 unknown, so only its left and right neighbours could bridge it, and row 4
        // unknown on the right of it.
        let mut c = map(20, 10, |x, y| x == 10 || (y == 4 && x > 10));
        c.projector_width = 200;
        for (i, m) in c.map.iter_mut().enumerate() {
            if let Some((px, _)) = m
                && i % 20 > 10
            {
                *px += 60;
            }
        }
        assert_eq!(step(&c).to_bits(), 2.0f64.to_bits());
        let (bridged, marked) = bridged(&c);
        for y in 0..10 {
            assert!(
                !marked[y * 20 + 10] && bridged[y * 20 + 10].is_none(),
                "row {y}"
            );
        }
        // On row 4 right of the edge, above and below agree: bridged on that surface.
        assert_eq!(bridged[4 * 20 + 15], Some((90, 8)));
        // Without the jump, column 10 is bridged between its neighbours.
        let (flat, _) = super::bridged(&map(20, 10, |x, _| x == 10));
        assert_eq!(flat[4 * 20 + 10], Some((20, 8)));
    }
}
