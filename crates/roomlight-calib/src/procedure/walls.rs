//! The room beyond the charts as measurements (issue 22, item 2): the camera sees every wall,
//! so tiles of its image become patches beside the charts' ([`super::Setup::wall_patches`]),
//! measured through the same captures (black level, attenuation, the LED target), so that the
//! objective asks for the LEDs' light everywhere a projector reaches, not only at the charts.
//!
//! A tile is sampled on a lattice (every `step`-th pixel of every `step`-th row): the light on
//! a wall varies slowly across a tile, the lattice's pixels average the camera noise down
//! nearly as well as every pixel would, and a simulated camera renders only the pixels read.
//! Tiles are left out where they would mix in what is not wall: the charts (their
//! quadrilaterals) and the projection-mapping target, both grown by a margin. Tiles no
//! projector lights are kept here and left out of the model later, once the attenuation shows
//! that no node reaches them ([`super::Target::without_unreached`]).

use crate::charts::ChartCorners;
use crate::nodes::dilate;

/// How the room beyond the charts is tiled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WallTiling {
    /// Tile side, camera pixels.
    pub tile: u32,
    /// The lattice's pitch inside a tile, camera pixels (1: every pixel).
    pub step: u32,
    /// Margin kept around the charts and the target, camera pixels.
    pub margin: u32,
}

impl Default for WallTiling {
    /// 24-pixel tiles read on a 4-pixel lattice (36 pixels each), 3 pixels clear of the charts
    /// and the target: in the lab's 1024×768 fisheye about 900 tiles fall on lit surfaces.
    fn default() -> Self {
        Self {
            tile: 24,
            step: 4,
            margin: 3,
        }
    }
}

/// Whether `(x, y)` lies inside the convex quadrilateral `q` (corners in order, either way
/// round; on an edge counts as inside).
fn in_quad(q: &[[f64; 2]; 4], x: f64, y: f64) -> bool {
    // Which side of every edge the point is on: all the same side (or on an edge) is inside.
    let (mut left, mut right) = (false, false);
    for k in 0..4 {
        let (a, b) = (q[k], q[(k + 1) % 4]);
        let cross = (b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0]);
        left |= cross > 0.0;
        right |= cross < 0.0;
    }
    !(left && right)
}

/// The camera pixels wall tiles must not read: inside a chart's quadrilateral or on the target,
/// grown by `margin` pixels. `target_mask` is `width` wide (its length gives the height).
pub fn wall_exclusion(
    corners: &[ChartCorners],
    target_mask: &[bool],
    width: u32,
    margin: u32,
) -> Vec<bool> {
    let w = width as usize;
    if w == 0 {
        return Vec::new();
    }
    let h = target_mask.len() / w;
    let mut out = target_mask[..w * h].to_vec();
    for chart in corners {
        let q = &chart.corners;
        // Only the quadrilateral's bounding box is tested; non-finite corners exclude nothing.
        let (lo, hi) = q
            .iter()
            .fold(([f64::MAX; 2], [f64::MIN; 2]), |(lo, hi), c| {
                (
                    [lo[0].min(c[0]), lo[1].min(c[1])],
                    [hi[0].max(c[0]), hi[1].max(c[1])],
                )
            });
        if !(lo[0].is_finite() && lo[1].is_finite() && hi[0].is_finite() && hi[1].is_finite()) {
            continue;
        }
        let clamp = |v: f64, n: usize| (v.max(0.0) as usize).min(n);
        for y in clamp(lo[1].floor(), h)..clamp(hi[1].ceil() + 1.0, h) {
            for x in clamp(lo[0].floor(), w)..clamp(hi[0].ceil() + 1.0, w) {
                if in_quad(q, x as f64 + 0.5, y as f64 + 0.5) {
                    out[y * w + x] = true;
                }
            }
        }
    }
    dilate(&out, w, h, margin)
}

/// Tiles of a `width`×`height` camera image as patches (camera pixel lists, tiles row by
/// row): each tile's lattice pixels not `exclude`d, kept when at least half of its lattice is.
/// Empty for a zero tile or step, or an `exclude` of the wrong size.
pub fn wall_patches(
    width: u32,
    height: u32,
    exclude: &[bool],
    tiling: &WallTiling,
) -> Vec<Vec<u32>> {
    let (w, h) = (width as usize, height as usize);
    let (tile, step) = (tiling.tile as usize, tiling.step as usize);
    if tile == 0 || step == 0 || exclude.len() != w * h {
        return Vec::new();
    }
    let mut out = Vec::new();
    for ty in (0..h).step_by(tile) {
        for tx in (0..w).step_by(tile) {
            let lattice: Vec<usize> = (ty + step / 2..(ty + tile).min(h))
                .step_by(step)
                .flat_map(|y| {
                    (tx + step / 2..(tx + tile).min(w))
                        .step_by(step)
                        .map(move |x| y * w + x)
                })
                .collect();
            let kept: Vec<u32> = lattice
                .iter()
                .filter(|&&i| !exclude[i])
                .map(|&i| i as u32)
                .collect();
            if kept.len() >= 4 && 2 * kept.len() >= lattice.len() {
                out.push(kept);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chart(corners: [[f64; 2]; 4]) -> ChartCorners {
        ChartCorners {
            name: "c".into(),
            corners,
        }
    }

    #[test]
    fn a_chart_and_the_target_are_excluded_with_their_margin() {
        let (w, h) = (40u32, 30u32);
        let mut target = vec![false; (w * h) as usize];
        target[(20 * w + 30) as usize] = true;
        let c = chart([[5.0, 5.0], [15.0, 5.0], [15.0, 12.0], [5.0, 12.0]]);
        let ex = wall_exclusion(&[c], &target, w, 2);
        let at = |x: u32, y: u32| ex[(y * w + x) as usize];
        assert!(at(10, 8), "inside the chart");
        // Pixel centres inside: x 5..=14, y 5..=11; grown by 2.
        assert!(
            at(3, 8) && at(16, 8) && at(10, 13),
            "within the margin of the chart"
        );
        assert!(!at(2, 8) && !at(17, 8) && !at(10, 14), "beyond the margin");
        assert!(
            at(30, 20) && at(32, 22) && !at(33, 20),
            "the target and its margin"
        );
        assert_eq!(ex.iter().filter(|e| **e).count(), 14 * 11 + 25);
    }

    #[test]
    fn a_tilted_chart_excludes_its_quadrilateral_not_its_box() {
        let (w, h) = (40u32, 40u32);
        let c = chart([[20.0, 2.0], [38.0, 20.0], [20.0, 38.0], [2.0, 20.0]]);
        let ex = wall_exclusion(&[c], &vec![false; (w * h) as usize], w, 0);
        assert!(ex[(20 * w + 20) as usize]);
        assert!(
            !ex[(3 * w + 3) as usize],
            "a corner of the box is outside the diamond"
        );
    }

    #[test]
    fn tiles_read_their_lattice_and_drop_when_mostly_excluded() {
        let (w, h) = (48u32, 24u32);
        let tiling = WallTiling {
            tile: 24,
            step: 4,
            margin: 0,
        };
        let mut ex = vec![false; (w * h) as usize];
        // The right tile is excluded but for a column of its lattice.
        for y in 0..h {
            for x in 24..w {
                ex[(y * w + x) as usize] = x != 26;
            }
        }
        let tiles = wall_patches(w, h, &ex, &tiling);
        assert_eq!(
            tiles.len(),
            1,
            "the right tile keeps 6 of 36 lattice pixels"
        );
        assert_eq!(tiles[0].len(), 36);
        assert!(tiles[0].iter().all(|&i| i % w % 4 == 2 && i / w % 4 == 2));
        // Half excluded: kept, with the other half.
        for y in 0..h {
            for x in 24..w {
                ex[(y * w + x) as usize] = x < 36;
            }
        }
        let tiles = wall_patches(w, h, &ex, &tiling);
        assert_eq!(tiles.len(), 2);
        assert_eq!(tiles[1].len(), 18);
        assert!(wall_patches(w, h, &ex[1..], &tiling).is_empty());
    }
}
