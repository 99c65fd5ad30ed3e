//! The reference optimum of DESIGN §3.5: exact bounded least squares
//! `min ½‖P x − (r − d)‖²  s.t.  0 ≤ x ≤ 1`, per channel.
//!
//! It is the yardstick every rule is measured against, not the distributed path. The interior
//! point solver `clarabel` finds the active set; the free variables are then solved exactly
//! (dense normal equations, Cholesky or, for rank-deficient problems, SVD) and the
//! projected-gradient residual certifies the result.

use crate::model::Problem;
use crate::rgb::LinearRgb;
use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus,
};
use nalgebra::{DMatrix, DVector};
use std::collections::HashMap;

/// Why the optimum could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OptimumError {
    /// The QP solver did not reach a solution.
    #[error("QP solver stopped on channel {channel} with status {status}")]
    Solver { channel: usize, status: String },
}

/// The exact optimum `x*`, `G*` of a problem.
#[derive(Debug, Clone, PartialEq)]
pub struct Optimum {
    /// `x*`, one value per node.
    pub x: Vec<LinearRgb>,
    /// `G*` per channel.
    pub objective_per_channel: [f64; 3],
    /// `G*` summed over the channels.
    pub objective: f64,
    /// `G` with every node black: the scale below which differences stop meaning anything.
    pub objective_black: f64,
    /// `max_n |x_n − clip(x_n − ∇G(x)_n)|` over nodes and channels: zero at an exact optimum.
    pub kkt_residual: f64,
}

impl Optimum {
    /// The excess `(G − G*) / G*` (DESIGN §3.5).
    ///
    /// When the target is reachable `G*` is (nearly) zero, so the denominator is floored at
    /// `1e-9 · G(black)`; with `G(black) = 0` too the excess is defined as 0.
    pub fn excess(&self, objective: f64) -> f64 {
        let floor = 1e-9 * self.objective_black;
        let den = self.objective.max(floor);
        if den > 0.0 {
            (objective - self.objective) / den
        } else {
            0.0
        }
    }
}

/// One channel of a problem as plain columns.
struct Channel {
    cols: Vec<(Vec<usize>, Vec<f64>)>,
    rhs: Vec<f64>,
}

impl Channel {
    fn new(problem: &Problem, c: usize) -> Self {
        let cols = problem
            .columns()
            .iter()
            .map(|col| {
                col.iter()
                    .filter(|(_, p)| p[c] > 0.0)
                    .map(|(i, p)| (i as usize, p[c]))
                    .unzip()
            })
            .collect();
        let rhs = problem
            .target()
            .iter()
            .zip(problem.black())
            .map(|(r, d)| r[c] - d[c])
            .collect();
        Self { cols, rhs }
    }

    fn nodes(&self) -> usize {
        self.cols.len()
    }

    /// Residual `r − d − P x`.
    fn residual(&self, x: &[f64]) -> Vec<f64> {
        let mut res = self.rhs.clone();
        for ((support, values), &xj) in self.cols.iter().zip(x) {
            for (&i, &p) in support.iter().zip(values) {
                res[i] -= p * xj;
            }
        }
        res
    }

    fn objective(&self, x: &[f64]) -> f64 {
        0.5 * self.residual(x).iter().map(|e| e * e).sum::<f64>()
    }

    /// `∇G = −Pᵀ(r − d − P x)`.
    fn gradient(&self, x: &[f64]) -> Vec<f64> {
        let res = self.residual(x);
        self.cols
            .iter()
            .map(|(support, values)| {
                -support
                    .iter()
                    .zip(values)
                    .map(|(&i, &p)| p * res[i])
                    .sum::<f64>()
            })
            .collect()
    }

    /// Upper-triangular entries of `PᵀP`, keyed by (row, col) with row ≤ col.
    fn gram(&self) -> HashMap<(usize, usize), f64> {
        let patches = self.rhs.len();
        let mut by_patch: Vec<Vec<(usize, f64)>> = vec![Vec::new(); patches];
        for (j, (support, values)) in self.cols.iter().enumerate() {
            for (&i, &p) in support.iter().zip(values) {
                by_patch[i].push((j, p));
            }
        }
        let mut gram = HashMap::new();
        for entries in &by_patch {
            for (a, &(j, pj)) in entries.iter().enumerate() {
                for &(k, pk) in &entries[a..] {
                    let key = (j.min(k), j.max(k));
                    *gram.entry(key).or_insert(0.0) += pj * pk;
                }
            }
        }
        gram
    }

    fn kkt_residual(&self, x: &[f64]) -> f64 {
        self.gradient(x)
            .iter()
            .zip(x)
            .map(|(g, &xj)| (xj - (xj - g).clamp(0.0, 1.0)).abs())
            .fold(0.0, f64::max)
    }
}

/// Solves the box QP of one channel with clarabel.
fn interior_point(
    ch: &Channel,
    gram: &HashMap<(usize, usize), f64>,
    channel: usize,
) -> Result<Vec<f64>, OptimumError> {
    let n = ch.nodes();
    // P (clarabel's name for the Hessian) as upper-triangular CSC.
    let mut entries: Vec<(usize, usize, f64)> =
        gram.iter().map(|(&(r, c), &v)| (r, c, v)).collect();
    entries.sort_by_key(|&(r, c, _)| (c, r));
    let mut colptr = vec![0usize; n + 1];
    let mut rowval = Vec::with_capacity(entries.len());
    let mut nzval = Vec::with_capacity(entries.len());
    for &(r, c, v) in &entries {
        colptr[c + 1] += 1;
        rowval.push(r);
        nzval.push(v);
    }
    for c in 0..n {
        colptr[c + 1] += colptr[c];
    }
    let hessian = CscMatrix::new(n, n, colptr, rowval, nzval);
    let q: Vec<f64> = ch.gradient(&vec![0.0; n]).into_iter().collect::<Vec<f64>>();
    // A = [I; −I], b = [1; 0]: x ≤ 1 and −x ≤ 0.
    let a = CscMatrix::new(
        2 * n,
        n,
        (0..=n).map(|j| 2 * j).collect(),
        (0..n).flat_map(|j| [j, n + j]).collect(),
        (0..n).flat_map(|_| [1.0, -1.0]).collect(),
    );
    let b: Vec<f64> = (0..2 * n).map(|k| if k < n { 1.0 } else { 0.0 }).collect();
    let cones = [NonnegativeConeT(2 * n)];
    let settings = DefaultSettingsBuilder::default()
        .verbose(false)
        .tol_gap_abs(1e-12)
        .tol_gap_rel(1e-12)
        .tol_feas(1e-12)
        .max_iter(200)
        .build()
        .map_err(|e| OptimumError::Solver {
            channel,
            status: format!("settings: {e}"),
        })?;
    let mut solver = DefaultSolver::new(&hessian, &q, &a, &b, &cones, settings).map_err(|e| {
        OptimumError::Solver {
            channel,
            status: format!("setup: {e:?}"),
        }
    })?;
    solver.solve();
    match solver.solution.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved | SolverStatus::MaxIterations => {
            let x: Vec<f64> = solver
                .solution
                .x
                .iter()
                .map(|v| v.clamp(0.0, 1.0))
                .collect();
            if x.iter().all(|v| v.is_finite()) {
                Ok(x)
            } else {
                Err(OptimumError::Solver {
                    channel,
                    status: "non-finite solution".into(),
                })
            }
        }
        other => Err(OptimumError::Solver {
            channel,
            status: format!("{other:?}"),
        }),
    }
}

/// Solves the free variables exactly for a given active set and returns the clipped result.
fn solve_free(
    ch: &Channel,
    gram: &HashMap<(usize, usize), f64>,
    x: &[f64],
    free: &[usize],
) -> Vec<f64> {
    let mut out = x.to_vec();
    if free.is_empty() {
        return out;
    }
    let mut fixed = x.to_vec();
    for &j in free {
        fixed[j] = 0.0;
    }
    let res = ch.residual(&fixed);
    let pos: HashMap<usize, usize> = free.iter().enumerate().map(|(k, &j)| (j, k)).collect();
    let f = free.len();
    let mut h = DMatrix::<f64>::zeros(f, f);
    for (&(r, c), &v) in gram {
        if let (Some(&a), Some(&b)) = (pos.get(&r), pos.get(&c)) {
            h[(a, b)] = v;
            h[(b, a)] = v;
        }
    }
    let rhs = DVector::from_iterator(
        f,
        free.iter().map(|&j| {
            let (support, values) = &ch.cols[j];
            support
                .iter()
                .zip(values)
                .map(|(&i, &p)| p * res[i])
                .sum::<f64>()
        }),
    );
    let solution = match h.clone().cholesky() {
        Some(chol) => Some(chol.solve(&rhs)),
        None => h.svd(true, true).solve(&rhs, 1e-13).ok(),
    };
    if let Some(sol) = solution
        && sol.iter().all(|v| v.is_finite())
    {
        for (k, &j) in free.iter().enumerate() {
            out[j] = sol[k].clamp(0.0, 1.0);
        }
    }
    out
}

/// Bounded least squares on one channel: interior point, then active-set polishing.
fn solve_channel(ch: &Channel, channel: usize) -> Result<Vec<f64>, OptimumError> {
    let n = ch.nodes();
    if n == 0 {
        return Ok(Vec::new());
    }
    let gram = ch.gram();
    let mut best = interior_point(ch, &gram, channel)?;
    let mut best_g = ch.objective(&best);
    // Active set from the interior point: variables near a bound with the gradient pushing
    // outwards are fixed there; the others are free. A few refinements repair misclassified
    // variables (free ones that left the box, fixed ones whose gradient points inwards).
    let bound_tol = 1e-7;
    let mut x = best.clone();
    for _ in 0..8 {
        let grad = ch.gradient(&x);
        let mut free = Vec::new();
        for j in 0..n {
            let at_lower = x[j] <= bound_tol && grad[j] >= 0.0;
            let at_upper = x[j] >= 1.0 - bound_tol && grad[j] <= 0.0;
            if at_lower {
                x[j] = 0.0;
            } else if at_upper {
                x[j] = 1.0;
            } else {
                free.push(j);
            }
        }
        let candidate = solve_free(ch, &gram, &x, &free);
        let g = ch.objective(&candidate);
        if g <= best_g {
            best_g = g;
            best = candidate.clone();
        }
        if ch.kkt_residual(&best) <= 1e-12 {
            break;
        }
        x = candidate;
    }
    Ok(best)
}

/// The exact bounded least-squares optimum of every channel.
pub fn optimum(problem: &Problem) -> Result<Optimum, OptimumError> {
    let mut x = vec![LinearRgb::ZERO; problem.nodes()];
    let mut per_channel = [0.0; 3];
    let mut black = 0.0;
    let mut kkt = 0.0f64;
    for (c, g_c) in per_channel.iter_mut().enumerate() {
        let ch = Channel::new(problem, c);
        let xc = solve_channel(&ch, c)?;
        *g_c = ch.objective(&xc);
        black += ch.objective(&vec![0.0; ch.nodes()]);
        kkt = kkt.max(ch.kkt_residual(&xc));
        for (xn, v) in x.iter_mut().zip(xc) {
            xn[c] = v;
        }
    }
    Ok(Optimum {
        x,
        objective_per_channel: per_channel,
        objective: per_channel.iter().sum(),
        objective_black: black,
        kkt_residual: kkt,
    })
}

/// The largest eigenvalue of `PᵀP` per channel, by power iteration from the all-ones vector
/// (which has a component along the Perron vector because `PᵀP ≥ 0`).
pub fn lambda_max(problem: &Problem) -> LinearRgb {
    let mut out = LinearRgb::ZERO;
    for c in 0..3 {
        let ch = Channel::new(problem, c);
        let n = ch.nodes();
        let mut v = vec![1.0 / (n.max(1) as f64).sqrt(); n];
        let mut lambda = 0.0;
        for _ in 0..10_000 {
            // w = PᵀP v = ∇G(v) with r − d = 0.
            let mut pv = vec![0.0; ch.rhs.len()];
            for ((support, values), &vj) in ch.cols.iter().zip(&v) {
                for (&i, &p) in support.iter().zip(values) {
                    pv[i] += p * vj;
                }
            }
            let w: Vec<f64> = ch
                .cols
                .iter()
                .map(|(s, vals)| s.iter().zip(vals).map(|(&i, &p)| p * pv[i]).sum())
                .collect();
            let rayleigh: f64 = w.iter().zip(&v).map(|(a, b)| a * b).sum();
            let norm = w.iter().map(|a| a * a).sum::<f64>().sqrt();
            // Zero norm: PᵀP v = 0, the matrix is zero on the reachable subspace.
            if norm == 0.0 {
                lambda = 0.0;
                break;
            }
            v = w.iter().map(|a| a / norm).collect();
            let converged = (rayleigh - lambda).abs() <= 1e-12 * rayleigh.abs();
            lambda = rayleigh;
            if converged {
                break;
            }
        }
        out[c] = lambda;
    }
    out
}

/// The best single fixed step `1/λ_max(PᵀP)` per channel: what only a central oracle knows
/// (DESIGN §3.2, the strongest fixed-step baseline). A channel with `λ_max = 0` gets 0.
pub fn global_step(problem: &Problem) -> LinearRgb {
    lambda_max(problem).map(|l| if l > 0.0 { 1.0 / l } else { 0.0 })
}
