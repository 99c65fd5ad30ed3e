//! A summed-area table of a projector frame's light: the mean over any pixel rectangle in O(1), so
//! that a radiosity element integrates the frame over the patch of surface it stands for.

use roomlight_core::LinearRgb;

/// Summed-area table of a projector frame's light: the mean over any rectangle in O(1). Entry
/// `(x, y)` holds the sum over `[0, x] × [0, y]` (inclusive), in the light's own buffer.
pub(super) struct SummedArea {
    width: usize,
    sums: Vec<LinearRgb>,
}

impl SummedArea {
    /// The table of a `width × height` frame's `light` (row by row), summed in place: the
    /// frame's light is gone, its buffer is the table ([`Self::into_buffer`] hands it back).
    /// Each entry adds its row's running sum to the entry above, left to right, in `f64`.
    pub(super) fn in_place(width: u32, mut light: Vec<LinearRgb>) -> Self {
        let w = width as usize;
        if w > 0 {
            for row in light.chunks_mut(w) {
                let mut sum = [0.0f64; 3];
                for l in row.iter_mut() {
                    for (s, v) in sum.iter_mut().zip(l.0) {
                        *s += v;
                    }
                    l.0 = sum;
                }
            }
            for i in w..light.len() {
                let (up, row) = (light[i - w].0, light[i].0);
                light[i] = LinearRgb([0, 1, 2].map(|c| up[c] + row[c]));
            }
        }
        Self {
            width: w,
            sums: light,
        }
    }

    /// The table's memory, for the next frame's light.
    pub(super) fn into_buffer(self) -> Vec<LinearRgb> {
        self.sums
    }

    /// Mean light over the half-open rectangle `[x0, x1) × [y0, y1)`; black when it is empty.
    pub(super) fn mean(&self, [x0, y0, x1, y1]: [u32; 4]) -> LinearRgb {
        let (x0, y0, x1, y1) = (x0 as usize, y0 as usize, x1 as usize, y1 as usize);
        let area = ((x1.saturating_sub(x0)) * (y1.saturating_sub(y0))) as f64;
        if area == 0.0 {
            return LinearRgb::ZERO;
        }
        // The sum over `[0, x) × [0, y)`: nothing on the first row or column.
        let at = |x: usize, y: usize| {
            if x == 0 || y == 0 {
                [0.0; 3]
            } else {
                self.sums[(y - 1) * self.width + x - 1].0
            }
        };
        let (a, b, c, d) = (at(x1, y1), at(x0, y1), at(x1, y0), at(x0, y0));
        LinearRgb([0, 1, 2].map(|k| (a[k] - b[k] - c[k] + d[k]) / area))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every rectangle's mean from the table is the mean of its pixels summed directly, empty
    /// rectangles are black, and the buffer comes back as long as the frame.
    #[test]
    fn means_match_direct_sums() {
        let (w, h) = (7u32, 5u32);
        let light: Vec<LinearRgb> = (0..w * h)
            .map(|i| {
                LinearRgb([
                    f64::from(i % 7) * 0.1,
                    f64::from(i / 7),
                    f64::from(i) * 0.01,
                ])
            })
            .collect();
        let table = SummedArea::in_place(w, light.clone());
        for (x0, y0, x1, y1) in [
            (0, 0, 7, 5),
            (2, 1, 5, 4),
            (6, 4, 7, 5),
            (0, 3, 1, 5),
            (3, 0, 7, 1),
        ] {
            let mut sum = [0.0f64; 3];
            for y in y0..y1 {
                for x in x0..x1 {
                    for (s, v) in sum.iter_mut().zip(light[(y * w + x) as usize].0) {
                        *s += v;
                    }
                }
            }
            let area = f64::from((x1 - x0) * (y1 - y0));
            let mean = table.mean([x0, y0, x1, y1]);
            for c in 0..3 {
                assert!(
                    (mean[c] - sum[c] / area).abs() < 1e-12,
                    "box {x0},{y0},{x1},{y1} channel {c}: {} against {}",
                    mean[c],
                    sum[c] / area
                );
            }
        }
        assert_eq!(table.mean([3, 2, 3, 4]).0.map(f64::to_bits), [0; 3]);
        assert_eq!(table.into_buffer().len(), (w * h) as usize);
    }
}
