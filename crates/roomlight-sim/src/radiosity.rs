//! Inter-reflection by radiosity on coarse surface elements (DESIGN §7): form factors with
//! visibility between element centres, made reciprocal and closed, then `B = ρ(E + F B)` solved
//! by Gauss–Seidel sweeps to a stated tolerance.

use crate::geometry::{EPS, Geometry};
use rayon::prelude::*;
use roomlight_core::LinearRgb;

/// Form factors of a closed room and the solver.
#[derive(Debug, Clone)]
pub struct Radiosity {
    n: usize,
    /// `F_ij`, row-major: the share of what leaves element i that reaches element j.
    form_factors: Vec<f32>,
    albedo: Vec<LinearRgb>,
    area: Vec<f32>,
}

/// The result of a solve.
#[derive(Debug, Clone)]
pub struct Solution {
    /// Indirect irradiance `H = F B` on each element.
    pub indirect: Vec<LinearRgb>,
    /// Radiosity (exitance) `B` of each element.
    pub radiosity: Vec<LinearRgb>,
    /// Sweeps used.
    pub sweeps: usize,
}

impl Radiosity {
    /// Computes the form factors between every pair of elements that see each other.
    ///
    /// The point-to-disk form `F_ij = A_j cos θ_i cos θ_j / (π r² + (A_i + A_j)/2)` keeps close
    /// pairs finite and makes `A_i F_ij` symmetric (reciprocity). For a closed room every row
    /// must sum to one; a symmetric scaling `K ← D K D` of `K_ij = A_i F_ij` restores that
    /// without breaking reciprocity (coarse elements otherwise lose or gain a few percent).
    pub fn build(geometry: &Geometry, closed: bool) -> Self {
        let els = &geometry.elements;
        let n = els.len();
        // Each element's pairs with the later ones on a core of its own (the visibility rays
        // dominate), then written both ways.
        let pairs: Vec<Vec<(usize, f32)>> = (0..n)
            .into_par_iter()
            .map(|i| {
                let (ci, ni, ai) = (els[i].center, els[i].normal, els[i].area);
                ((i + 1)..n)
                    .filter_map(|j| {
                        let (cj, nj, aj) = (els[j].center, els[j].normal, els[j].area);
                        let d = cj - ci;
                        let r2 = d.length_squared();
                        if r2 <= 1e-12 {
                            return None;
                        }
                        let r = r2.sqrt();
                        let cos_i = ni.dot(d) / r;
                        let cos_j = -nj.dot(d) / r;
                        if cos_i <= 1e-4
                            || cos_j <= 1e-4
                            || !geometry.visible(ci + ni * EPS, cj + nj * EPS)
                        {
                            return None;
                        }
                        let kij =
                            ai * aj * cos_i * cos_j / (std::f32::consts::PI * r2 + 0.5 * (ai + aj));
                        Some((j, kij))
                    })
                    .collect()
            })
            .collect();
        let mut k = vec![0.0f32; n * n];
        for (i, row) in pairs.into_iter().enumerate() {
            for (j, kij) in row {
                k[i * n + j] = kij;
                k[j * n + i] = kij;
            }
        }
        let area: Vec<f32> = els.iter().map(|e| e.area).collect();
        if closed {
            let mut d = vec![1.0f64; n];
            for _ in 0..200 {
                let mut worst = 0.0f64;
                for i in 0..n {
                    let row: f64 = (0..n).map(|j| f64::from(k[i * n + j]) * d[j]).sum();
                    // A row with no partner (an element nobody sees) keeps its scale.
                    if row > 0.0 {
                        let target = f64::from(area[i]);
                        let next = (d[i] * target / row).sqrt();
                        worst = worst.max((d[i] * row / target - 1.0).abs());
                        d[i] = next;
                    }
                }
                if worst < 1e-6 {
                    break;
                }
            }
            for i in 0..n {
                for j in 0..n {
                    k[i * n + j] = (f64::from(k[i * n + j]) * d[i] * d[j]) as f32;
                }
            }
        }
        // F_ij = K_ij / A_i; an element of zero area has no row.
        for i in 0..n {
            let inv = if area[i] > 0.0 { 1.0 / area[i] } else { 0.0 };
            for j in 0..n {
                k[i * n + j] *= inv;
            }
        }
        Self {
            n,
            form_factors: k,
            albedo: els.iter().map(|e| e.albedo).collect(),
            area,
        }
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.n
    }

    /// True without elements.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// `F_ij`.
    pub fn form_factor(&self, i: usize, j: usize) -> f32 {
        self.form_factors[i * self.n + j]
    }

    /// Element areas.
    pub fn areas(&self) -> &[f32] {
        &self.area
    }

    /// Solves `B = ρ ⊙ (E + F B)` for direct irradiance `E` on the elements, until no
    /// element's `B` changes by more than `tolerance` times the largest `B` (or 500 sweeps).
    pub fn solve(&self, direct: &[LinearRgb], tolerance: f64) -> Solution {
        let n = self.n;
        let mut b: Vec<[f32; 3]> = (0..n)
            .map(|i| to3(self.albedo[i].hadamard(direct[i])))
            .collect();
        let mut h = vec![[0.0f32; 3]; n];
        let mut sweeps = 0;
        for sweep in 1..=500 {
            sweeps = sweep;
            let mut change = 0.0f32;
            let mut largest = 0.0f32;
            for i in 0..n {
                let row = &self.form_factors[i * n..(i + 1) * n];
                let mut acc = [0.0f32; 3];
                for (f, bj) in row.iter().zip(&b) {
                    acc[0] += f * bj[0];
                    acc[1] += f * bj[1];
                    acc[2] += f * bj[2];
                }
                h[i] = acc;
                for c in 0..3 {
                    let next = self.albedo[i][c] as f32 * (direct[i][c] as f32 + acc[c]);
                    change = change.max((next - b[i][c]).abs());
                    largest = largest.max(next.abs());
                    b[i][c] = next;
                }
            }
            if f64::from(change) <= tolerance * f64::from(largest) {
                break;
            }
        }
        Solution {
            indirect: h.into_iter().map(from3).collect(),
            radiosity: b.into_iter().map(from3).collect(),
            sweeps,
        }
    }
}

fn to3(v: LinearRgb) -> [f32; 3] {
    [v[0] as f32, v[1] as f32, v[2] as f32]
}

fn from3(v: [f32; 3]) -> LinearRgb {
    LinearRgb([f64::from(v[0]), f64::from(v[1]), f64::from(v[2])])
}
