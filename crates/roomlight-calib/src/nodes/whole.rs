//! A projector as one node over its whole frame: a large aperture, or a luminaire that lights
//! no chart. Its pixels that land on the target are black, and so is a margin around them.
//!
//! A large aperture is defocused by design. It decodes where it is in focus (the desk it hangs
//! over) and rarely on the target, which stands out of that plane. Taking only the pixels
//! decoded on the target then left the lab's area light with no black at all: it lit the bust
//! in full, and a dark target could only turn it off (docs/results.md). So the target's pixels
//! in the projector are also outlined by the pixels decoded around it in the camera (within
//! [`OUTLINE_PX`]), and the convex hull of that outline is black too. The outline is larger
//! than the target (the camera sees past it onto what lies behind it): the room loses some of
//! the area light around the target, which the other projectors and the shading make up
//! (docs/results.md has what it cost). Making the outline a node of its own, for the rounds to
//! weigh, cost the lab's bring-up 32 captures and was not kept.
//!
//! Hand-written: the convex hull (Andrew's monotone chain) of a few hundred points and its
//! fill. No crate in the workspace has one; `geo` would bring a geometry stack for one polygon.

use super::mask::dilate;
use crate::charts::ChartCorners;
use crate::graycode::Correspondence;

/// Projector pixels kept dark around the target for a whole-frame node, as a share of the
/// frame's width: a large aperture's light blurs away from the focus plane, and pixels the
/// decode missed are dark only through this.
const WHOLE_FRAME_TARGET_MARGIN: f64 = 0.06;

/// Camera pixels within this distance of the target outline it: their decodes, around a target
/// the projector does not decode, surround the target's pixels in the projector too.
pub const OUTLINE_PX: u32 = 8;

/// An outline point farther from the outline's median than this many times the median
/// distance (plus [`STRAY_SLACK_PX`]) is a stray decode, left out of the hull: one wrong decode
/// must not black out half a frame.
const STRAY_FACTOR: f64 = 3.0;
const STRAY_SLACK_PX: f64 = 2.0;

/// A projector as one node (a large aperture, or a luminaire that lights no chart): weights 1
/// over its whole frame except the pixels that land on the target ([`on_target`]: decoded
/// there, or inside its outline), dilated by a margin of 6% of the frame's width; its chart for
/// the conventional start is the one it lights over the most camera pixels, if any.
pub fn whole_frame(
    corr: &Correspondence,
    corners: &[ChartCorners],
    target: &[bool],
) -> (Vec<f32>, Option<usize>) {
    let (w, h) = (corr.projector_width, corr.projector_height);
    let margin = (WHOLE_FRAME_TARGET_MARGIN * f64::from(w)).ceil() as u32;
    let dark = dilate(&on_target(corr, target), w as usize, h as usize, margin);
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

/// The projector pixels that land on the target as far as `corr` tells: those decoded on it,
/// and inside the convex hull of those decoded on it or within [`OUTLINE_PX`] camera pixels of
/// it (stray decodes left out). Nothing when `target` is not the camera's size.
pub fn on_target(corr: &Correspondence, target: &[bool]) -> Vec<bool> {
    let (w, h) = (
        corr.projector_width as usize,
        corr.projector_height as usize,
    );
    let (cw, ch) = (corr.width as usize, corr.height as usize);
    let mut dark = vec![false; w * h];
    if target.len() != cw * ch || corr.map.len() != cw * ch || !target.contains(&true) {
        return dark;
    }
    let near = dilate(target, cw, ch, OUTLINE_PX);
    let mut outline = Vec::new();
    for (i, m) in corr.map.iter().enumerate() {
        if let (Some((x, y)), true) = (m, near[i])
            && (*x as usize) < w
            && (*y as usize) < h
        {
            if target[i] {
                dark[*y as usize * w + *x as usize] = true;
            }
            outline.push([f64::from(*x), f64::from(*y)]);
        }
    }
    let hull = convex_hull(without_strays(outline));
    if hull.len() < 3 {
        return dark;
    }
    let (lo, hi) = hull.iter().fold(
        ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
        |(lo, hi), p| {
            (
                [lo[0].min(p[0]), lo[1].min(p[1])],
                [hi[0].max(p[0]), hi[1].max(p[1])],
            )
        },
    );
    // The hull's points are pixel indices within the frame, so its box is too.
    for y in lo[1] as usize..=(hi[1] as usize).min(h - 1) {
        for x in lo[0] as usize..=(hi[0] as usize).min(w - 1) {
            if in_convex(&hull, [x as f64, y as f64]) {
                dark[y * w + x] = true;
            }
        }
    }
    dark
}

/// The points within [`STRAY_FACTOR`] × their median distance (+ [`STRAY_SLACK_PX`]) of their
/// median point (per coordinate).
fn without_strays(points: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    let median = |mut v: Vec<f64>| -> f64 {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    let centre = [
        median(points.iter().map(|p| p[0]).collect()),
        median(points.iter().map(|p| p[1]).collect()),
    ];
    let distance = |p: &[f64; 2]| (p[0] - centre[0]).hypot(p[1] - centre[1]);
    let typical = median(points.iter().map(distance).collect());
    let limit = STRAY_FACTOR * typical + STRAY_SLACK_PX;
    points
        .into_iter()
        .filter(|p| distance(p) <= limit)
        .collect()
}

/// The convex hull, its turns positive by [`cross`] (clockwise on a screen, whose y points
/// down), without collinear points; fewer than three points when they are fewer or all on a
/// line.
fn convex_hull(mut points: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    points.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    points.dedup();
    if points.len() < 3 {
        return points;
    }
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * points.len());
    let chain = |hull: &mut Vec<[f64; 2]>, p: [f64; 2], floor: usize| {
        while hull.len() >= floor + 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
        {
            hull.pop();
        }
        hull.push(p);
    };
    // The lower chain left to right, then the upper one back, on top of the lower's last point.
    for p in &points {
        chain(&mut hull, *p, 0);
    }
    let floor = hull.len() - 1;
    for p in points.iter().rev().skip(1) {
        chain(&mut hull, *p, floor);
    }
    // The last point is the first again.
    hull.pop();
    hull
}

/// `(b − a) × (c − a)`: positive when `a, b, c` turn counter-clockwise in `(x, y)`.
fn cross(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// Whether `p` lies in the convex polygon `hull` of [`convex_hull`] (its edges included).
fn in_convex(hull: &[[f64; 2]], p: [f64; 2]) -> bool {
    (0..hull.len()).all(|i| cross(hull[i], hull[(i + 1) % hull.len()], p) >= 0.0)
}

/// Whether `(x, y)` lies inside the convex quadrilateral `q`.
fn inside(q: &[[f64; 2]; 4], x: f64, y: f64) -> bool {
    let side = |a: [f64; 2], b: [f64; 2]| (b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0]);
    let s: Vec<f64> = (0..4).map(|i| side(q[i], q[(i + 1) % 4])).collect();
    s.iter().all(|&v| v >= 0.0) || s.iter().all(|&v| v <= 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera that sees a 64 × 48 projector pixel for pixel, with a disc-shaped target of
    /// radius 8 at (40, 20) the projector does not decode (`decoded_on_target` false), and one
    /// stray decode beside it at `stray`.
    fn room(decoded_on_target: bool, stray: Option<(u32, u32)>) -> (Correspondence, Vec<bool>) {
        let (w, h) = (64u32, 48u32);
        let on = |x: u32, y: u32| (f64::from(x) - 40.0).hypot(f64::from(y) - 20.0) <= 8.0;
        let target: Vec<bool> = (0..w * h).map(|i| on(i % w, i / w)).collect();
        let mut corr = Correspondence::identity(w, h);
        if !decoded_on_target {
            for (m, t) in corr.map.iter_mut().zip(&target) {
                if *t {
                    *m = None;
                }
            }
        }
        if let Some(p) = stray {
            // A camera pixel just outside the disc, decoded far away.
            corr.map[(20 * w + 50) as usize] = Some(p);
        }
        (corr, target)
    }

    #[test]
    fn a_target_the_projector_does_not_decode_is_outlined_by_its_surroundings() {
        let (corr, target) = room(false, None);
        let dark = on_target(&corr, &target);
        // Every pixel that lands on the target is black, though none of them decoded.
        let missed = (0..target.len()).filter(|&i| target[i] && !dark[i]).count();
        assert_eq!(missed, 0, "target pixels left lit");
        // The hull stays near the target: its outline is at most OUTLINE_PX outside it along
        // each axis (the camera mask's dilation is square).
        for (i, d) in dark.iter().enumerate() {
            let (x, y) = ((i % 64) as f64, (i / 64) as f64);
            let r = (x - 40.0).hypot(y - 20.0);
            assert!(
                !d || r <= 8.0 + f64::from(OUTLINE_PX) * 2f64.sqrt() + 1.5,
                "({x}, {y}) dark"
            );
        }
        // With the margin, the node's weights: black on the target, 1 far from it.
        let (weights, _) = whole_frame(&corr, &[], &target);
        assert!((0..target.len()).all(|i| !target[i] || weights[i] == 0.0));
        assert!(
            weights[47 * 64] > 0.5,
            "a far corner is lit: {}",
            weights[47 * 64]
        );
        // The old rule (decoded target pixels only) kept nothing dark here.
        assert!(corr.map.iter().zip(&target).all(|(m, t)| !t || m.is_none()));
    }

    #[test]
    fn a_stray_decode_does_not_black_out_the_frame() {
        let (clean, target) = room(false, None);
        let (corr, _) = room(false, Some((2, 45)));
        let dark = on_target(&corr, &target);
        assert_eq!(
            dark,
            on_target(&clean, &target),
            "the stray point is left out"
        );
        assert!(!dark[45 * 64 + 2] && !dark[40 * 64 + 10]);
    }

    #[test]
    fn a_decoded_target_stays_dark_and_no_target_darkens_nothing() {
        let (corr, target) = room(true, None);
        let dark = on_target(&corr, &target);
        assert!((0..target.len()).all(|i| !target[i] || dark[i]));
        let (weights, _) = whole_frame(&corr, &[], &target);
        assert!((0..target.len()).all(|i| !target[i] || weights[i] == 0.0));
        let (weights, _) = whole_frame(&corr, &[], &vec![false; target.len()]);
        assert!(weights.iter().all(|&w| w > 0.5), "no target, nothing black");
        assert!(!on_target(&corr, &vec![false; target.len()]).contains(&true));
        assert!(
            !on_target(&corr, &target[1..]).contains(&true),
            "a mask of the wrong size"
        );
    }

    #[test]
    fn the_hull_of_a_square_with_inner_and_collinear_points_is_its_corners() {
        let mut points = vec![[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0], [2.0, 2.0]];
        points.extend([[2.0, 0.0], [4.0, 2.0], [0.0, 0.0]]);
        let hull = convex_hull(points);
        assert_eq!(hull.len(), 4, "{hull:?}");
        assert!(in_convex(&hull, [2.0, 2.0]) && in_convex(&hull, [4.0, 4.0]));
        assert!(!in_convex(&hull, [4.5, 2.0]) && !in_convex(&hull, [-0.1, 1.0]));
        assert!(convex_hull(vec![[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]).len() < 3);
    }
}
