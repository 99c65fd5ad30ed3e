//! A summed-area table of a projector frame's light: the mean over any pixel rectangle in O(1), so
//! that a radiosity element integrates the frame over the patch of surface it stands for.

use roomlight_core::LinearRgb;

/// Summed-area table of a projector frame's light: the mean over any rectangle in O(1).
pub(super) struct SummedArea {
    width: usize,
    sums: Vec<[f64; 3]>,
}

impl SummedArea {
    pub(super) fn new(width: u32, height: u32, light: impl Fn(usize) -> LinearRgb) -> Self {
        let (w, h) = (width as usize, height as usize);
        let mut sums = vec![[0.0f64; 3]; (w + 1) * (h + 1)];
        for y in 0..h {
            let mut row = [0.0f64; 3];
            for x in 0..w {
                let l = light(y * w + x);
                for (r, v) in row.iter_mut().zip(l.0) {
                    *r += v;
                }
                let above = sums[y * (w + 1) + x + 1];
                sums[(y + 1) * (w + 1) + x + 1] = [0, 1, 2].map(|c| above[c] + row[c]);
            }
        }
        Self { width: w, sums }
    }

    /// Mean light over the half-open rectangle `[x0, x1) × [y0, y1)`; black when it is empty.
    pub(super) fn mean(&self, [x0, y0, x1, y1]: [u32; 4]) -> LinearRgb {
        let (x0, y0, x1, y1) = (x0 as usize, y0 as usize, x1 as usize, y1 as usize);
        let area = ((x1.saturating_sub(x0)) * (y1.saturating_sub(y0))) as f64;
        if area == 0.0 {
            return LinearRgb::ZERO;
        }
        let at = |x: usize, y: usize| self.sums[y * (self.width + 1) + x];
        let (a, b, c, d) = (at(x1, y1), at(x0, y1), at(x1, y0), at(x0, y0));
        LinearRgb([0, 1, 2].map(|k| (a[k] - b[k] - c[k] + d[k]) / area))
    }
}
