//! Black offset, attenuation `p` and white response `s` (DESIGN §4.1, §4.5, §4.7): one node at a
//! time (N + 1 captures), Hadamard S-matrix multiplexing (same count, lower variance), and the
//! differential measurement of one node while the others keep their values.

use crate::CalibError;
use crate::charts::{PatchSample, PatchStatus};
use roomlight_core::{AttenuationColumn, LinearRgb};

/// How nodes are switched on for the attenuation captures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scheme {
    /// Node `i` alone in capture `i`.
    OneAtATime,
    /// Rows of an S-matrix of order `2^k − 1 ≥ N` (Sylvester construction): about half the
    /// nodes on in every capture; variance lower by about `(n+1)²/(4n)`.
    Hadamard,
}

/// The S-matrix order used for `nodes` nodes: the smallest `2^k − 1 ≥ nodes`.
pub fn s_order(nodes: usize) -> usize {
    let mut n = 1;
    while n < nodes {
        n = 2 * n + 1;
    }
    n
}

/// `S_ij` of the S-matrix of order `n = 2^k − 1`: 1 where the Sylvester Hadamard matrix of order
/// `n + 1` has −1 (rows and columns shifted by one past its all-ones border).
fn s_entry(i: usize, j: usize) -> bool {
    ((i + 1) & (j + 1)).count_ones() % 2 == 1
}

/// Which nodes are on in each capture (the black capture, all off, is taken separately).
pub fn plan(nodes: usize, scheme: Scheme) -> Vec<Vec<bool>> {
    match scheme {
        Scheme::OneAtATime => (0..nodes)
            .map(|i| (0..nodes).map(|j| i == j).collect())
            .collect(),
        Scheme::Hadamard => {
            let n = s_order(nodes);
            (0..n)
                .map(|i| (0..nodes).map(|j| s_entry(i, j)).collect())
                .collect()
        }
    }
}

/// Measured attenuation of every node on every patch.
#[derive(Debug, Clone, PartialEq)]
pub struct Attenuation {
    /// Black offset `d` per patch.
    pub black: Vec<LinearRgb>,
    /// `p_{n,i}` per node and patch.
    pub dense: Vec<Vec<LinearRgb>>,
    /// Standard deviation of each `p_{n,i}` from the patch noise.
    pub sigma: Vec<Vec<LinearRgb>>,
    /// False for patches left out of some capture (saturated, out of the image) or crossed by
    /// an edge (see `usable`).
    pub usable: Vec<bool>,
}

fn check_captures(
    what: &'static str,
    captures: &[&[PatchSample]],
    patches: usize,
) -> Result<(), CalibError> {
    for (k, c) in captures.iter().enumerate() {
        if c.len() != patches {
            return Err(CalibError::Invalid {
                field: what,
                problem: format!("capture {k} has {} patches, expected {patches}", c.len()),
            });
        }
    }
    Ok(())
}

/// Solves for `p` from the black capture and the captures of `plan(nodes, scheme)`.
pub fn solve(
    scheme: Scheme,
    nodes: usize,
    black: &[PatchSample],
    captures: &[Vec<PatchSample>],
) -> Result<Attenuation, CalibError> {
    let rows = plan(nodes, scheme);
    if captures.len() != rows.len() {
        return Err(CalibError::Invalid {
            field: "attenuation captures",
            problem: format!(
                "{} captures, the {scheme:?} plan for {nodes} nodes needs {}",
                captures.len(),
                rows.len()
            ),
        });
    }
    let patches = black.len();
    let all: Vec<&[PatchSample]> = captures.iter().map(|c| c.as_slice()).collect();
    check_captures("attenuation captures", &all, patches)?;
    let usable = usable(scheme, black, captures);
    let mut dense = vec![vec![LinearRgb::ZERO; patches]; nodes];
    let mut sigma = vec![vec![LinearRgb::ZERO; patches]; nodes];
    match scheme {
        Scheme::OneAtATime => {
            for (n, c) in captures.iter().enumerate() {
                for i in (0..patches).filter(|&i| usable[i]) {
                    dense[n][i] = c[i].mean - black[i].mean;
                    sigma[n][i] = (c[i].std_error.hadamard(c[i].std_error)
                        + black[i].std_error.hadamard(black[i].std_error))
                    .map(f64::sqrt);
                }
            }
        }
        Scheme::Hadamard => {
            // S⁻¹ = 2/(n+1) · (2Sᵀ − J): p_j = Σ_i w_ji (y_i − d) with w_ji = 2/(n+1)·(2S_ij − 1).
            let n = rows.len();
            let k = 2.0 / (n as f64 + 1.0);
            for j in 0..nodes {
                let w: Vec<f64> = (0..n)
                    .map(|i| k * (if s_entry(i, j) { 2.0 } else { 0.0 } - 1.0))
                    .collect();
                let w_sum: f64 = w.iter().sum();
                for i in (0..patches).filter(|&i| usable[i]) {
                    let mut p = LinearRgb::ZERO;
                    let mut var = LinearRgb::ZERO;
                    for (r, c) in captures.iter().enumerate() {
                        p += (c[i].mean - black[i].mean) * w[r];
                        var += c[i].std_error.hadamard(c[i].std_error) * (w[r] * w[r]);
                    }
                    var += black[i].std_error.hadamard(black[i].std_error) * (w_sum * w_sum);
                    dense[j][i] = p;
                    sigma[j][i] = var.map(f64::sqrt);
                }
            }
        }
    }
    Ok(Attenuation {
        black: black.iter().map(|b| b.mean).collect(),
        dense,
        sigma,
        usable,
    })
}

/// Which patches every capture measured and none found crossed by an edge. An edge through a
/// patch (a node boundary, a frustum or shadow edge) shows wherever the light on either side of
/// it differs: with Hadamard rows, in at least two captures (any two S-matrix columns differ in
/// (n+1)/2 rows, and a projector is on in as many). A single flag among them is one capture's
/// noise crossing the test, which made the model's patches (and G* with them, threefold in the
/// quick demo) depend on the seed; such a patch stays in, decided once for the session. One
/// node at a time, an edge may show in one capture only, so there any flag leaves it out.
fn usable(scheme: Scheme, black: &[PatchSample], captures: &[Vec<PatchSample>]) -> Vec<bool> {
    let flags_allowed = match scheme {
        Scheme::OneAtATime => 0,
        Scheme::Hadamard => 1,
    };
    let measured = |s: &PatchSample| matches!(s.status, PatchStatus::Ok | PatchStatus::NonUniform);
    (0..black.len())
        .map(|i| {
            let all = std::iter::once(&black[i]).chain(captures.iter().map(|c| &c[i]));
            let flags = all
                .clone()
                .filter(|s| s.status == PatchStatus::NonUniform)
                .count();
            all.clone().all(measured) && flags <= flags_allowed
        })
        .collect()
}

impl Attenuation {
    /// Sparse columns keeping the entries above `sigmas · σ` (DESIGN §2), negatives clipped to 0.
    pub fn columns(&self, sigmas: f64) -> Result<Vec<AttenuationColumn>, CalibError> {
        self.dense
            .iter()
            .zip(&self.sigma)
            .map(|(p, s)| {
                let clipped: Vec<LinearRgb> = p
                    .iter()
                    .zip(&self.usable)
                    .map(|(v, &u)| {
                        if u {
                            v.map(|x| x.max(0.0))
                        } else {
                            LinearRgb::ZERO
                        }
                    })
                    .collect();
                let threshold: Vec<LinearRgb> = s.iter().map(|v| *v * sigmas).collect();
                AttenuationColumn::from_dense_with_cutoff(&clipped, &threshold).map_err(|e| {
                    CalibError::Invalid {
                        field: "attenuation",
                        problem: e.to_string(),
                    }
                })
            })
            .collect()
    }
}

/// `s = y(all white) − d`: the response to every node at white (DESIGN §3.3), one capture.
pub fn white_response(
    black: &[PatchSample],
    all_white: &[PatchSample],
) -> Result<Vec<LinearRgb>, CalibError> {
    check_captures("white capture", &[all_white], black.len())?;
    Ok(black
        .iter()
        .zip(all_white)
        .map(|(b, w)| {
            if b.status == PatchStatus::Ok && w.status == PatchStatus::Ok {
                (w.mean - b.mean).map(|v| v.max(0.0))
            } else {
                LinearRgb::ZERO
            }
        })
        .collect())
}

/// Hot calibration (DESIGN §4.7): one node at 1 and at 0 while every other node keeps its value;
/// the difference is its column, whatever the rest of the room shows.
pub fn differential(
    at_one: &[PatchSample],
    at_zero: &[PatchSample],
) -> Result<(Vec<LinearRgb>, Vec<LinearRgb>), CalibError> {
    check_captures("differential captures", &[at_one], at_zero.len())?;
    Ok(at_one
        .iter()
        .zip(at_zero)
        .map(|(a, b)| {
            if a.status == PatchStatus::Ok && b.status == PatchStatus::Ok {
                (
                    a.mean - b.mean,
                    (a.std_error.hadamard(a.std_error) + b.std_error.hadamard(b.std_error))
                        .map(f64::sqrt),
                )
            } else {
                (LinearRgb::ZERO, LinearRgb::ZERO)
            }
        })
        .unzip())
}
