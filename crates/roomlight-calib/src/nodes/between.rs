//! Where an undecoded projector pixel lands in the camera, read between the decoded ones
//! (issue 21, item 7). [`super::inverse_map`] gives a projector pixel no camera pixel decoded
//! the camera pixel of its nearest decoded neighbour in projector space. On a surface the
//! projector grazes, a narrow band of its columns covers many camera pixels, too dim to
//! decode; the band's projector pixels then all take the camera pixel of a decoded island
//! inside it or of its edge, where its footprint still has a share, while the other projectors,
//! which see no footprint of it over the band, give all their light there: the band was lit
//! twice (the lab's wall-right over the desk's side, weights summing to 1.1–1.4).
//!
//! Reading the camera position between the decoded pixels on either side of a gap, along the
//! projector's row and its column, puts such a pixel where it lands, so the blend can see that
//! it lands outside its own footprint, where the others already give everything.
//! Hand-written: a two-pass scan for the nearest decoded pixel on each side and a linear
//! interpolation, which no image crate offers on a sparse correspondence.

/// The farthest (projector pixels) a decoded pixel may be on either side of a gap to read
/// between: a grazing band of the lab is about 15 columns wide; further apart the two sides
/// may lie on different surfaces.
pub(super) const BETWEEN_RADIUS: usize = 32;

/// For every projector pixel `hops` says was filled (`hops > 0`), the camera pixel between the
/// nearest pixels with a camera pixel of their own (`hops == 0`) on either side within
/// [`BETWEEN_RADIUS`], along its row and its column: the linear interpolation of theirs by
/// distance, the mean of the row's and the column's where both read one. `None` where neither
/// has pixels on both sides, and for pixels not filled. `inv` gives camera pixel indices of a
/// camera `cw` pixels wide; projector `pw`×`ph`.
pub(super) fn between(
    inv: &[Option<u32>],
    hops: &[u32],
    (pw, ph): (usize, usize),
    cw: usize,
) -> Vec<Option<u32>> {
    let own = |p: usize| if hops[p] == 0 { inv[p] } else { None };
    let at = |i: u32| ((i as usize % cw) as f64, (i as usize / cw) as f64);
    // Per axis, for every pixel: the estimate from its two sides, as (x, y).
    let mut sum = vec![(0.0f64, 0.0f64, 0u8); pw * ph];
    let mut scan = |line: &[usize]| {
        let n = line.len();
        let mut before: Vec<Option<(usize, u32)>> = vec![None; n];
        let mut last = None;
        for (t, &p) in line.iter().enumerate() {
            if let Some(i) = own(p) {
                last = Some((t, i));
            }
            before[t] = last.filter(|(s, _)| t - s <= BETWEEN_RADIUS);
        }
        let mut next = None;
        for t in (0..n).rev() {
            let p = line[t];
            if let Some(i) = own(p) {
                next = Some((t, i));
            }
            if hops[p] == 0 {
                continue;
            }
            let after = next.filter(|(s, _)| s - t <= BETWEEN_RADIUS);
            if let (Some((a, ia)), Some((b, ib))) = (before[t], after) {
                // a < t < b: the pixel lies strictly between two of its own.
                let f = (t - a) as f64 / (b - a) as f64;
                let ((xa, ya), (xb, yb)) = (at(ia), at(ib));
                let s = &mut sum[p];
                s.0 += xa + f * (xb - xa);
                s.1 += ya + f * (yb - ya);
                s.2 += 1;
            }
        }
    };
    let mut line = Vec::with_capacity(pw.max(ph));
    for y in 0..ph {
        line.clear();
        line.extend((0..pw).map(|x| y * pw + x));
        scan(&line);
    }
    for x in 0..pw {
        line.clear();
        line.extend((0..ph).map(|y| y * pw + x));
        scan(&line);
    }
    sum.into_iter()
        .map(|(x, y, n)| {
            // No estimate: None (the caller keeps the nearest neighbour's camera pixel).
            (n > 0).then(|| {
                let (x, y) = (x / n as f64, y / n as f64);
                (y.round() as usize * cw + x.round() as usize) as u32
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_gap_reads_between_its_sides_and_an_open_end_reads_nothing() {
        // A 6×1 projector over a camera 100 wide: pixels 0 and 4 decoded at camera x 10 and 50
        // (row 2), 1–3 filled between them, 5 filled beyond the last decoded one.
        let (pw, ph, cw) = (6, 1, 100);
        let c = |x: usize| Some((2 * cw + x) as u32);
        let inv = vec![c(10), c(10), c(10), c(50), c(50), c(50)];
        let hops = vec![0, 1, 2, 1, 0, 1];
        let b = between(&inv, &hops, (pw, ph), cw);
        assert_eq!(
            b[0], None,
            "a pixel with its own camera pixel is not read between"
        );
        assert_eq!(b[1], c(20));
        assert_eq!(b[2], c(30));
        assert_eq!(b[3], c(40));
        assert_eq!(
            b[5], None,
            "beyond the last decoded pixel there is no other side"
        );
    }

    #[test]
    fn sides_further_than_the_radius_are_not_read_between() {
        let n = BETWEEN_RADIUS + 2;
        let cw = 1000;
        let mut inv = vec![Some(0u32); n];
        inv[n - 1] = Some(900);
        let mut hops = vec![1u32; n];
        hops[0] = 0;
        hops[n - 1] = 0;
        let b = between(&inv, &hops, (n, 1), cw);
        // Pixel 1 is 1 from the left side and n − 2 = RADIUS from the right: read.
        assert!(b[1].is_some());
        // Pixel n − 2 is RADIUS from the left and 1 from the right: read.
        assert!(b[n - 2].is_some());
        let mut far = hops.clone();
        far[0] = 1;
        // With the left side gone, nothing lies on both sides of any pixel.
        assert!(between(&inv, &far, (n, 1), cw).iter().all(Option::is_none));
    }

    #[test]
    fn the_row_and_the_column_are_averaged() {
        // 3×3 projector, centre filled; left/right decoded at camera (0, 0) and (20, 0), above and
        // below at (10, 10) and (10, 30): the row reads (10, 0), the column (10, 20): (10, 10).
        let cw = 100;
        let at = |x: usize, y: usize| Some((y * cw + x) as u32);
        let mut inv = vec![None; 9];
        let mut hops = vec![5u32; 9];
        for (p, i) in [
            (3, at(0, 0)),
            (5, at(20, 0)),
            (1, at(10, 10)),
            (7, at(10, 30)),
        ] {
            inv[p] = i;
            hops[p] = 0;
        }
        inv[4] = at(0, 0);
        hops[4] = 1;
        assert_eq!(between(&inv, &hops, (3, 3), cw)[4], at(10, 10));
    }
}
