//! Decoding pixels with several untrusted bits from their decoded neighbours (the fill step
//! of [`super::decode`]). It owns the prediction from neighbours and the choice among nearby
//! codes; it must not know where the captures came from.

use super::*;

/// How far (projector pixels) a candidate may lie from the neighbours' prediction.
const FILL_RADIUS: i64 = 8;
/// The share of the measured differences (by magnitude) a filled pixel's code must agree with:
/// a pixel in shadow next to a lit surface sees that surface's code in its inter-reflected
/// light, which agrees with no single position that well.
const FILL_AGREEMENT: f32 = 0.9;
/// How many times a pixel is tried as its neighbours fill in.
const FILL_TRIES: u8 = 3;

/// The second pass of [`decode`]: a reached pixel with more than one untrusted bit (a weak
/// direct signal next to strong global light, or a surface at grazing incidence where
/// pattern-dependent inter-reflection flips weak bits) is decoded from its decoded neighbours,
/// growing inwards from them. Per axis, the neighbours predict its coordinate (a linear
/// extrapolation of two neighbours in a row where there are such, else the neighbours
/// themselves); of the coordinates within [`FILL_RADIUS`] of the prediction that agree with
/// every trusted bit, the one whose code correlates best with the measured differences is taken
/// when it agrees with [`FILL_AGREEMENT`] of them and beats every candidate more than one pixel
/// away by six noise standard deviations and half the direct light. Otherwise the pixel stays
/// unknown: across a depth edge the prediction is wrong and no candidate agrees clearly.
/// With [`DecodeConfig::resolve_edges`], a pixel no candidate is clear for, whose direct light
/// dominates, is resolved among the coordinates its neighbours span ([`neighbour_range`],
/// [`resolve_pixel`]): a pixel on a stripe edge that every pattern shares (XOR coding's base
/// edges) shows no difference at all, and only its neighbours say which edge it is on.
#[allow(clippy::too_many_arguments)]
pub(super) fn fill_from_neighbours(
    manifest: &Manifest,
    config: &DecodeConfig,
    (w, h): (usize, usize),
    reached: &impl Fn(usize) -> bool,
    reading: &impl Fn(usize, &mut Vec<Reading>),
    (direct, dominant): (&[f32], &[bool]),
    map: &mut [Option<(u32, u32)>],
    confidence: &mut [f32],
) {
    let grid = Grid { w, h };
    let mut tries = vec![0u8; w * h];
    let mut readings = Vec::new();
    let mut queue: VecDeque<usize> = VecDeque::new();
    let push_around =
        |i: usize, map: &[Option<(u32, u32)>], tries: &mut [u8], queue: &mut VecDeque<usize>| {
            for dir in AROUND {
                if let Some(j) = grid.at(i, dir, 1)
                    && map[j].is_none()
                    && tries[j] < FILL_TRIES
                    && reached(j)
                {
                    tries[j] += 1;
                    queue.push_back(j);
                }
            }
        };
    for i in 0..w * h {
        if map[i].is_some() {
            push_around(i, map, &mut tries, &mut queue);
        }
    }
    while let Some(i) = queue.pop_front() {
        if map[i].is_some() {
            continue;
        }
        let mut predictions = grid.predictions(i, map);
        reading(i, &mut readings);
        let ld = direct[i];
        let found = match (
            best_on_axis(manifest, Axis::Column, &readings, &mut predictions[0], ld),
            best_on_axis(manifest, Axis::Row, &readings, &mut predictions[1], ld),
        ) {
            // At most a quarter: where a measured pixel lands on the same projector pixel the
            // inverse map mostly prefers it.
            (Some((x, x_gap)), Some((y, y_gap))) => Some((
                (x, y),
                0.25 * (x_gap.min(y_gap) / (2.0 * ld).max(f32::MIN_POSITIVE)).min(1.0),
            )),
            // Only where direct light dominates: pattern-dependent reflected light can make a
            // dim pixel fit a code near its neighbours' that is not its own.
            _ if config.resolve_edges && dominant[i] => neighbour_range(grid, i, map)
                .and_then(|near| resolve_pixel(manifest, &readings, ld, Some(near)))
                .map(|(xy, c)| (xy, 0.25 * c)),
            _ => None,
        };
        let Some((xy, c)) = found else {
            continue;
        };
        map[i] = Some(xy);
        confidence[i] = c;
        push_around(i, map, &mut tries, &mut queue);
    }
}

/// Per axis, the range of the coordinates of pixel `i`'s decoded neighbours, where at least
/// three are decoded and they span at most [`EDGE_SPAN`] pixels: a smooth surface seen at no
/// more than about one and a half projector pixels per camera pixel (a surface at grazing
/// incidence, or a depth edge, is not resolved this way).
fn neighbour_range(grid: Grid, i: usize, map: &[Option<(u32, u32)>]) -> Option<[(i64, i64); 2]> {
    let around: Vec<(u32, u32)> = AROUND
        .iter()
        .filter_map(|&dir| grid.at(i, dir, 1).and_then(|j| map[j]))
        .collect();
    if around.len() < 3 {
        return None;
    }
    let range = |f: fn(&(u32, u32)) -> u32| {
        let lo = around.iter().map(f).min().map(i64::from)?;
        let hi = around.iter().map(f).max().map(i64::from)?;
        (hi - lo <= EDGE_SPAN).then_some((lo, hi))
    };
    Some([range(|a| a.0)?, range(|a| a.1)?])
}

/// The widest range of neighbours' coordinates [`neighbour_range`] resolves within: narrower
/// than the four pixels between two edges every XOR-04 pattern shares.
const EDGE_SPAN: i64 = 3;

/// The eight neighbours of a pixel, as steps.
const AROUND: [(isize, isize); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

/// The camera image as row-major pixel indices.
#[derive(Debug, Clone, Copy)]
struct Grid {
    w: usize,
    h: usize,
}

impl Grid {
    /// The pixel `k` steps from `i` in direction `(dx, dy)`, if inside the image.
    fn at(self, i: usize, (dx, dy): (isize, isize), k: isize) -> Option<usize> {
        let w = self.w;
        let (x, y) = ((i % w) as isize + dx * k, (i / w) as isize + dy * k);
        (x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < self.h)
            .then(|| y as usize * w + x as usize)
    }

    /// Predictions per axis of pixel `i`'s projector coordinates from its decoded neighbours:
    /// linear extrapolations of two neighbours in a row where there are any, else the adjacent
    /// neighbours' own coordinates.
    fn predictions(self, i: usize, map: &[Option<(u32, u32)>]) -> [Vec<i64>; 2] {
        let (mut extrapolated, mut adjacent): ([Vec<i64>; 2], [Vec<i64>; 2]) = Default::default();
        for dir in AROUND {
            let Some(a) = self.at(i, dir, 1).and_then(|j| map[j]) else {
                continue;
            };
            let b = self.at(i, dir, 2).and_then(|j| map[j]);
            for (k, (va, vb)) in [(a.0, b.map(|b| b.0)), (a.1, b.map(|b| b.1))]
                .into_iter()
                .enumerate()
            {
                adjacent[k].push(i64::from(va));
                if let Some(vb) = vb {
                    extrapolated[k].push(2 * i64::from(va) - i64::from(vb));
                }
            }
        }
        [0, 1].map(|k| {
            if extrapolated[k].is_empty() {
                std::mem::take(&mut adjacent[k])
            } else {
                std::mem::take(&mut extrapolated[k])
            }
        })
    }
}

/// One axis of [`fill_from_neighbours`]: the coordinate near the median of `predictions` whose
/// code agrees with every trusted reading and best with all of them, with its lead over every
/// candidate more than one pixel away; `None` when no candidate is clear.
fn best_on_axis(
    manifest: &Manifest,
    axis: Axis,
    readings: &[Reading],
    predictions: &mut [i64],
    ld: f32,
) -> Option<(u32, f32)> {
    predictions.sort_unstable();
    let centre = *predictions.get(predictions.len() / 2)?;
    let size = i64::from(manifest.cells(axis));
    let ours: Vec<&Reading> = readings.iter().filter(|r| r.axis == axis).collect();
    let noise = ours.iter().map(|r| r.sigma).sum::<f32>() / ours.len().max(1) as f32;
    let candidates: Vec<(i64, f32)> = ((centre - FILL_RADIUS).max(0)
        ..=(centre + FILL_RADIUS).min(size - 1))
        .filter_map(|v| {
            let mut score = 0.0f32;
            for r in &ours {
                let e = manifest.encoded_bit(axis, r.bit, v as u32);
                if r.trusted.is_some_and(|t| t != e) {
                    return None;
                }
                score += if e { r.d } else { -r.d };
            }
            Some((v, score))
        })
        .collect();
    let &(best, score) = candidates.iter().max_by(|a, b| a.1.total_cmp(&b.1))?;
    // No rival at all (every other candidate disagrees with a trusted bit): an infinite lead.
    let rival = candidates
        .iter()
        .filter(|(v, _)| (v - best).abs() > 1)
        .map(|c| c.1)
        .fold(f32::NEG_INFINITY, f32::max);
    let gap = score - rival;
    let total: f32 = ours.iter().map(|r| r.d.abs()).sum();
    // NaN differences (a corrupt capture) fail both comparisons.
    (score >= FILL_AGREEMENT * total && gap >= (6.0 * noise).max(0.5 * ld))
        .then_some((best as u32, gap))
}
