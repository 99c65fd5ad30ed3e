//! Values on a grid of blocks of projector pixels, shared by the nodes' shape
//! ([`crate::procedure::shape`]) and per-pixel shading ([`crate::shading`]): carrying read values
//! into unread blocks, and a nearest-rank quantile. Hand-written: a breadth-first fill over a
//! grid and a selection, a few lines each.

use std::collections::VecDeque;

/// Carries every `Some` of `values` (row-major, `across` blocks a row) into the `None` blocks
/// around it, breadth first, up to `steps` blocks away; a block takes the value of the first
/// read block that reaches it. Returns whether any block was read at all.
pub(crate) fn fill<T: Copy>(values: &mut [Option<T>], across: usize, steps: u32) -> bool {
    if across == 0 {
        return false;
    }
    let down = values.len() / across;
    let mut taken = vec![0u32; values.len()];
    let mut queue: VecDeque<usize> = (0..values.len()).filter(|&b| values[b].is_some()).collect();
    let any = !queue.is_empty();
    while let Some(b) = queue.pop_front() {
        if taken[b] >= steps {
            continue;
        }
        let (x, y) = (b % across, b / across);
        let around = [
            (x > 0).then(|| b - 1),
            (x + 1 < across).then(|| b + 1),
            (y > 0).then(|| b - across),
            (y + 1 < down).then(|| b + across),
        ];
        for n in around.into_iter().flatten() {
            if values[n].is_none() {
                values[n] = values[b];
                taken[n] = taken[b] + 1;
                queue.push_back(n);
            }
        }
    }
    any
}

/// Nearest-rank quantile `q` of `v` (reordered); `None` when empty.
pub(crate) fn quantile(v: &mut [f64], q: f64) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let k = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1;
    let (_, x, _) = v.select_nth_unstable_by(k, f64::total_cmp);
    Some(*x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fill_carries_values_so_many_blocks_and_no_further() {
        // 5 × 1 blocks, one read at the left end.
        let mut v = [Some(7), None, None, None, None];
        assert!(fill(&mut v, 5, 2));
        assert_eq!(v, [Some(7), Some(7), Some(7), None, None]);
        let mut none: [Option<u8>; 4] = [None; 4];
        assert!(!fill(&mut none, 2, 2));
        assert_eq!(none, [None; 4]);
    }

    #[test]
    fn quantiles_are_nearest_rank() {
        let mut v = [5.0, 1.0, 4.0, 2.0, 3.0];
        assert_eq!(quantile(&mut v, 0.5), Some(3.0));
        assert_eq!(quantile(&mut v, 0.0), Some(1.0));
        assert_eq!(quantile(&mut v, 1.0), Some(5.0));
        assert_eq!(quantile(&mut [], 0.5), None);
    }
}
