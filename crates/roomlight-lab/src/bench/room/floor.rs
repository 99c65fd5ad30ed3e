//! The noise floor of a case: how close to the optimum noisy captures let the rounds come.
//!
//! A capture measures `y + n`, `n` the camera's noise, so the errors the nodes act on are
//! `(r − n) − y`: rounds that converged on that capture (its model rounds do exactly that)
//! land on the exact optimum `x̃` of the measured model with the target `r − n`, not on `x*`.
//! The floor is the excess of that optimum on the noiseless model, `(G(x̃) − G*)/G*`, for the
//! noise of real captures of the run (noisy minus noiseless sampling of the same frame). Where
//! it is above 1%, 1% is out of reach for any rule on single captures, and the case is judged
//! against the floor instead.

use anyhow::Result;
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
}

impl Floor {
    /// The floor itself is above the 1% goal: the goal cannot be met on single captures.
    pub fn above_goal(&self) -> bool {
        self.median > 1e-2
    }
}

/// The floor of `problem` (optimum `best`) under each capture noise of `noise` (one value per
/// patch each); `None` without any.
pub fn floor(problem: &Problem, best: &Optimum, noise: &[Vec<LinearRgb>]) -> Result<Option<Floor>> {
    let mut excess = noise
        .iter()
        .map(|n| {
            let noisy = optimum(&noisy_problem(problem, n)?)?;
            Ok(best.excess(problem.objective(&noisy.x)))
        })
        .collect::<Result<Vec<f64>>>()?;
    if excess.is_empty() {
        return Ok(None);
    }
    let samples = excess.len();
    let level = excess.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Ok(Some(Floor {
        median: super::records::median(&mut excess),
        level,
        samples,
    }))
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
