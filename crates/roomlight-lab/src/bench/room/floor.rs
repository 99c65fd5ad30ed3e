//! The noise floor of a case: how close to the optimum noisy captures let the rounds come.
//!
//! A capture measures `y + n`, `n` the camera's noise, so the errors the nodes act on are
//! `(r − n) − y`: rounds that converged on that capture (its model rounds do exactly that)
//! land on the exact optimum `x̃` of the measured model with the target `r − n`, not on `x*`.
//! The floor is the excess of that optimum on the noiseless model, `(G(x̃) − G*)/G*`, for the
//! noise of real captures of the run (noisy minus noiseless sampling of the same frame). Where
//! it is above 1%, 1% is out of reach for any rule on single captures, and the case is judged
//! against the floor instead.
//!
//! That optimum takes the model for the room. The captures measure the room itself, `P x + d`
//! with its true transport, while the nodes' steps come from the model's columns `P̂`, which
//! miss whatever light fell below the calibration's noise cut (more of it the noisier the
//! camera): the rounds stop where the projected step `P̂ᵀ (r − n − P x − d)` vanishes, not at
//! `x̃`. The floor is the model excess of that fixed point (found by the rule's own iteration,
//! from `x̃`); with the model equal to the room it is `x̃`'s.

use anyhow::{Result, bail};
use roomlight_core::optimum::{Optimum, optimum};
use roomlight_core::{LinearRgb, Problem};
use serde::Serialize;

/// A case's floor over a few captures' noise.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Floor {
    /// The median floor.
    pub median: f64,
    /// The largest: the level a case whose floor is above 1% is judged against.
    pub level: f64,
    /// Captures whose noise it was computed from.
    pub samples: usize,
    /// The median excess of `x̃`, the noise's share alone (the model taken for the room).
    pub noise_only: f64,
}

impl Floor {
    /// The floor itself is above the 1% goal: the goal cannot be met on single captures.
    pub fn above_goal(&self) -> bool {
        self.median > 1e-2
    }
}

/// The floor of `problem` (optimum `best`) in `room` (the true transport, black and target on
/// the same patches and nodes) under each capture noise of `noise` (one value per patch each);
/// `None` without any.
pub fn floor(
    problem: &Problem,
    room: &Problem,
    best: &Optimum,
    noise: &[Vec<LinearRgb>],
) -> Result<Option<Floor>> {
    if (room.nodes(), room.patches()) != (problem.nodes(), problem.patches()) {
        bail!(
            "floor: the room has {} nodes and {} patches, the model {} and {}",
            room.nodes(),
            room.patches(),
            problem.nodes(),
            problem.patches()
        );
    }
    let (mut excess, mut noise_only): (Vec<f64>, Vec<f64>) = noise
        .iter()
        .map(|n| {
            let noisy = optimum(&noisy_problem(problem, n)?)?;
            let fixed = settled(problem, room, n, &noisy.x);
            Ok((
                best.excess(problem.objective(&fixed)),
                best.excess(problem.objective(&noisy.x)),
            ))
        })
        .collect::<Result<Vec<(f64, f64)>>>()?
        .into_iter()
        .unzip();
    if excess.is_empty() {
        return Ok(None);
    }
    let samples = excess.len();
    let level = excess.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Ok(Some(Floor {
        median: super::records::median(&mut excess),
        level,
        samples,
        noise_only: super::records::median(&mut noise_only),
    }))
}

/// Iterations of [`settled`] at most; it stops earlier once no value moves by `SETTLED_STEP`.
const SETTLED_ITERATIONS: usize = 20_000;
const SETTLED_STEP: f64 = 1e-9;

/// Where the rounds stop on one capture's noise `n`: the fixed point of the safe step
/// `x ← clip(x + P̂ᵀ e / h)` (DESIGN §3.3, θ = 1, `h = P̂ᵀ P̂ 1` of the model `problem`) with the
/// errors `e = r̂ − n − (P x + d)` the camera measures in `room` against the model's target
/// `r̂`; from `start`. A node channel whose `h` is 0 (no light on any patch) does not move.
fn settled(
    problem: &Problem,
    room: &Problem,
    n: &[LinearRgb],
    start: &[LinearRgb],
) -> Vec<LinearRgb> {
    let s = problem.white_response();
    let h: Vec<LinearRgb> = problem
        .columns()
        .iter()
        .map(|c| {
            c.iter()
                .fold(LinearRgb::ZERO, |h, (i, p)| h + p.hadamard(s[i as usize]))
        })
        .collect();
    let mut x = start.to_vec();
    for _ in 0..SETTLED_ITERATIONS {
        let y = room.response(&x);
        let e: Vec<LinearRgb> = problem
            .target()
            .iter()
            .zip(&y)
            .zip(n)
            .map(|((r, y), n)| *r - *n - *y)
            .collect();
        let mut moved = 0.0_f64;
        for ((xn, column), hn) in x.iter_mut().zip(problem.columns()).zip(&h) {
            let g = column
                .iter()
                .fold(LinearRgb::ZERO, |g, (i, p)| g + p.hadamard(e[i as usize]));
            let mut next = *xn;
            for c in 0..3 {
                // No light of this node in this channel: no step (and no division by 0).
                if hn[c] > 0.0 {
                    next[c] += g[c] / hn[c];
                }
            }
            let next = next.clamp_unit();
            moved = moved.max((next - *xn).max_abs());
            *xn = next;
        }
        if moved < SETTLED_STEP {
            break;
        }
    }
    x
}

/// `problem` as one capture with noise `n` sees it: errors `(r − n) − (P x + d)`. Where
/// `r − n` would be negative (a dark patch), the target is 0 and the black offset takes the
/// rest, `d + n − r`: the same errors, with a target and black that stay nonnegative.
fn noisy_problem(problem: &Problem, n: &[LinearRgb]) -> Result<Problem> {
    let (mut black, mut target) = (problem.black().to_vec(), problem.target().to_vec());
    for ((d, r), n) in black.iter_mut().zip(target.iter_mut()).zip(n) {
        for c in 0..3 {
            let shifted = r[c] - n[c];
            if shifted >= 0.0 {
                r[c] = shifted;
            } else {
                d[c] -= shifted;
                r[c] = 0.0;
            }
        }
    }
    Ok(Problem::new(
        problem.columns().to_vec(),
        black,
        target,
        problem.noise().to_vec(),
    )?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use roomlight_core::AttenuationColumn;

    fn problem(column: [f64; 3]) -> Problem {
        let dense: Vec<LinearRgb> = column.iter().map(|&p| LinearRgb::splat(p)).collect();
        let column = AttenuationColumn::from_dense_with_cutoff(&dense, &[LinearRgb::ZERO; 3])
            .expect("a column");
        Problem::new(
            vec![column],
            vec![LinearRgb::ZERO; 3],
            [0.6, 0.6, 0.3].map(LinearRgb::splat).to_vec(),
            vec![LinearRgb::splat(0.01); 3],
        )
        .expect("a problem")
    }

    /// One node lighting two patches as the model has it (1, 1) and as the room does (1, 0.5):
    /// the model's optimum is x = 0.6 (excess 0), but the rounds, whose steps come from the
    /// model's column and whose errors from the room, stop where (0.6 − x) + (0.6 − 0.5 x) = 0,
    /// x = 0.8: G = ½ (0.2² + 0.2² + 0.3²) against G* = ½ 0.3², an excess of 8/9.
    #[test]
    fn the_floor_is_where_the_rounds_stop_in_the_room() {
        let model = problem([1.0, 1.0, 0.0]);
        let room = problem([1.0, 0.5, 0.0]);
        let best = optimum(&model).expect("the optimum");
        let noise = vec![vec![LinearRgb::ZERO; 3]; 2];
        let f = floor(&model, &room, &best, &noise)
            .expect("a floor")
            .expect("two samples");
        assert_eq!(f.samples, 2);
        assert!((f.median - 8.0 / 9.0).abs() < 1e-6, "{f:?}");
        assert!((f.level - 8.0 / 9.0).abs() < 1e-6, "{f:?}");
        assert!(f.noise_only.abs() < 1e-6, "{f:?}");
        // The room the model describes: the floor is the noisy optimum's.
        let same = floor(&model, &model, &best, &noise)
            .expect("a floor")
            .expect("two samples");
        assert!(same.median.abs() < 1e-6, "{same:?}");
    }
}
