//! Shared helpers for the core's integration tests: random problems and a brute-force optimum.
#![allow(dead_code)]

use nalgebra::{DMatrix, DVector};
use proptest::prelude::*;
use roomlight_core::{AttenuationColumn, LinearRgb, Problem};

/// A random nonnegative problem with the awkward features the issue names: zero entries,
/// zero columns, duplicated columns, targets brighter than all-white and darker than black.
pub fn problem_strategy(max_nodes: usize, max_patches: usize) -> impl Strategy<Value = Problem> {
    (1..=max_nodes, 2..=max_patches, any::<u64>())
        .prop_map(|(n, m, seed)| random_problem(n, m, seed))
}

/// Deterministic random problem from a seed (a small xorshift keeps it independent of `rand`).
pub fn random_problem(n: usize, m: usize, seed: u64) -> Problem {
    let mut state = seed | 1;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut dense: Vec<Vec<LinearRgb>> = (0..n)
        .map(|_| {
            (0..m)
                .map(|_| {
                    if next() < 0.4 {
                        LinearRgb::ZERO
                    } else {
                        LinearRgb([next(), next(), next()])
                    }
                })
                .collect()
        })
        .collect();
    let feature = next();
    if n >= 2 && feature < 0.25 {
        dense[1] = dense[0].clone(); // duplicated column
    } else if feature < 0.45 {
        dense[n - 1] = vec![LinearRgb::ZERO; m]; // a node nobody sees
    }
    let columns: Vec<AttenuationColumn> = dense
        .iter()
        .map(|d| {
            AttenuationColumn::from_dense_with_cutoff(d, &vec![LinearRgb::ZERO; m])
                .expect("valid column")
        })
        .collect();
    let black: Vec<LinearRgb> = (0..m)
        .map(|_| LinearRgb([next(), next(), next()]) * 0.05)
        .collect();
    let white: Vec<LinearRgb> = (0..m)
        .map(|i| dense.iter().fold(black[i], |acc, col| acc + col[i]))
        .collect();
    let regime = next();
    let target: Vec<LinearRgb> = (0..m)
        .map(|i| {
            if regime < 0.2 {
                white[i] * 1.5 + LinearRgb::splat(0.1) // brighter than all-white
            } else if regime < 0.35 {
                black[i] * 0.5 // darker than black
            } else {
                {
                    let k = next() * 1.2;
                    black[i] + (white[i] - black[i]) * k
                }
            }
        })
        .collect();
    Problem::new(columns, black, target, vec![LinearRgb::splat(1e-3); m]).expect("valid problem")
}

/// The exact optimum by enumerating every active set (lower, upper, free) of every channel.
/// Exponential: for tests with at most ~6 nodes.
pub fn brute_force_objective(problem: &Problem) -> f64 {
    let n = problem.nodes();
    let m = problem.patches();
    let mut total = 0.0;
    for c in 0..3 {
        let p = DMatrix::from_fn(m, n, |i, j| problem.columns()[j].get(i as u32)[c]);
        let b = DVector::from_fn(m, |i, _| problem.target()[i][c] - problem.black()[i][c]);
        let mut best = f64::INFINITY;
        for code in 0..3usize.pow(n as u32) {
            let mut x = DVector::zeros(n);
            let mut free = Vec::new();
            let mut k = code;
            for j in 0..n {
                match k % 3 {
                    0 => x[j] = 0.0,
                    1 => x[j] = 1.0,
                    _ => free.push(j),
                }
                k /= 3;
            }
            if !free.is_empty() {
                let fixed_res = &b - &p * &x;
                let pf = DMatrix::from_fn(m, free.len(), |i, k| p[(i, free[k])]);
                let Ok(sol) = pf.svd(true, true).solve(&fixed_res, 1e-12) else {
                    continue;
                };
                if sol.iter().any(|v| !(-1e-12..=1.0 + 1e-12).contains(v)) {
                    continue;
                }
                for (k, &j) in free.iter().enumerate() {
                    x[j] = sol[k].clamp(0.0, 1.0);
                }
            }
            let g = 0.5 * (&b - &p * &x).norm_squared();
            best = best.min(g);
        }
        total += best;
    }
    total
}
