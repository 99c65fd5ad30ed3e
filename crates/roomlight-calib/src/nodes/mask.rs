//! Camera- and projector-space masks: the chamfer distance to a mask's edge, dilation and
//! erosion over square neighbourhoods. Hand-written: a few loops over `Vec<bool>` images,
//! smaller than bringing an image-processing crate's types to and from them.

/// Distance (chamfer, in pixels) from every pixel inside `mask` to the nearest pixel outside it;
/// 0 outside, infinite where the whole image is inside. The image's border is no edge: a
/// footprint the view cuts goes on beyond it.
pub(super) fn distance_inside(mask: &[bool], w: usize, h: usize) -> Vec<f32> {
    const D: f32 = std::f32::consts::SQRT_2;
    let mut d: Vec<f32> = mask
        .iter()
        .map(|&m| if m { f32::INFINITY } else { 0.0 })
        .collect();
    let at = |x: isize, y: isize, d: &[f32]| {
        if x < 0 || y < 0 || x >= w as isize || y >= h as isize {
            f32::INFINITY
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
pub(super) fn erode(mask: &[bool], w: usize, h: usize, r: u32) -> Vec<bool> {
    let inverted: Vec<bool> = mask.iter().map(|m| !m).collect();
    dilate(&inverted, w, h, r).into_iter().map(|m| !m).collect()
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
