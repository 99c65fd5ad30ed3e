//! Synthetic rooms for benchmarks and tests: nodes on a grid of walls, one 24-patch chart per
//! node, direct light on the node's own chart, spill onto neighbouring charts where projector
//! footprints overlap, and inter-reflection coupling that decays with distance. No rendering:
//! the transport is written down directly, so a thousand nodes cost milliseconds to build.

use crate::colorchecker;
use crate::model::{AttenuationColumn, ModelError, PatchId, Problem, patch_id};
use crate::rgb::LinearRgb;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Patches per chart.
pub const PATCHES_PER_CHART: usize = 24;

/// How to build a synthetic room.
#[derive(Debug, Clone, PartialEq)]
pub struct SyntheticConfig {
    /// Number of nodes (and charts).
    pub nodes: usize,
    /// Seed of every random choice.
    pub seed: u64,
    /// Strength of inter-reflection: 1 for an ordinary room, about 3 for an albedo-0.9 room.
    pub interreflection: f64,
    /// Share of nodes that are dim (a large-aperture projector gives ~15% of a standard one).
    pub dim_share: f64,
    /// Target illuminance relative to a standard node's direct light (≈ the `x` it needs).
    pub target_level: f64,
    /// Noise `σ` of a patch mean at black; it grows with the square root of the signal.
    pub noise_floor: f64,
    /// Entries at or below `cutoff_sigmas · σ_i` are dropped from the supports (DESIGN §2);
    /// 0 keeps every entry the generator writes.
    pub cutoff_sigmas: f64,
    /// Scale of every transport entry (camera exposure): the paper's fixed step depends on it.
    pub exposure: f64,
}

impl SyntheticConfig {
    /// An ordinary room of `nodes` nodes.
    pub fn new(nodes: usize, seed: u64) -> Self {
        Self {
            nodes,
            seed,
            interreflection: 1.0,
            dim_share: 0.1,
            target_level: 0.5,
            noise_floor: 5e-4,
            cutoff_sigmas: 3.0,
            exposure: 1.0,
        }
    }
}

/// A synthetic room: the problem and each node's own chart.
#[derive(Debug, Clone)]
pub struct SyntheticRoom {
    /// The model.
    pub problem: Problem,
    /// `charts[n]`: the patches of node `n`'s own chart (empty for a node without a chart).
    pub charts: Vec<Vec<PatchId>>,
}

/// Builds a synthetic room.
pub fn synthetic_room(config: &SyntheticConfig) -> Result<SyntheticRoom, ModelError> {
    let n = config.nodes;
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let grid = Grid {
        side: (n as f64).sqrt().ceil().max(1.0) as usize,
        nodes: n,
    };
    let rho = colorchecker::reflectances();
    let patches = n * PATCHES_PER_CHART;
    let gains = node_gains(config, &mut rng);
    let illuminance = target_illuminance(config, grid);
    let black: Vec<LinearRgb> = (0..patches)
        .map(|i| rho[i % PATCHES_PER_CHART] * (0.002 * config.exposure))
        .collect();
    let target_clean: Vec<LinearRgb> = (0..patches)
        .map(|i| rho[i % PATCHES_PER_CHART].hadamard(illuminance[i / PATCHES_PER_CHART]) + black[i])
        .collect();
    let columns = gains
        .iter()
        .enumerate()
        .map(|(node, gain)| node_column(config, grid, node, *gain, &target_clean))
        .collect::<Result<Vec<_>, _>>()?;
    let noise: Vec<LinearRgb> = target_clean
        .iter()
        .map(|&t| noise_sigma(config.noise_floor, t))
        .collect();
    let charts = (0..n)
        .map(|m| {
            (m * PATCHES_PER_CHART..(m + 1) * PATCHES_PER_CHART)
                .map(patch_id)
                .collect::<Result<Vec<_>, _>>()
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(SyntheticRoom {
        problem: Problem::new(columns, black, target_clean, noise)?,
        charts,
    })
}

/// The nodes (and their charts) on a square grid of walls, row by row.
#[derive(Debug, Clone, Copy)]
struct Grid {
    side: usize,
    nodes: usize,
}

impl Grid {
    /// Where node (or chart) `k` sits, in grid units.
    fn position(self, k: usize) -> (f64, f64) {
        ((k % self.side) as f64, (k / self.side) as f64)
    }
}

/// Per-node peak output: a slight colour tint, and some nodes dim (drawn node by node).
fn node_gains(config: &SyntheticConfig, rng: &mut ChaCha8Rng) -> Vec<LinearRgb> {
    (0..config.nodes)
        .map(|_| {
            let base = if rng.random::<f64>() < config.dim_share {
                0.15
            } else {
                rng.random_range(0.7..1.0)
            };
            LinearRgb([
                base * rng.random_range(0.9..1.1),
                base,
                base * rng.random_range(0.9..1.1),
            ]) * (0.3 * config.exposure)
        })
        .collect()
}

/// The LED target illuminance at each chart: smooth over the room, warm to cool.
fn target_illuminance(config: &SyntheticConfig, grid: Grid) -> Vec<LinearRgb> {
    (0..config.nodes)
        .map(|m| {
            let (x, y) = grid.position(m);
            let wave = 1.0 + 0.3 * (0.7 * x).sin() * (0.5 * y).cos();
            let warm = 0.5 + 0.5 * (0.3 * x + 0.2 * y).sin();
            let tint = LinearRgb([1.0 + 0.15 * warm, 1.0, 1.0 - 0.15 * warm]);
            tint * (wave * config.target_level * 0.3 * 0.85 * config.exposure)
        })
        .collect()
}

/// One node's attenuation column: direct light on its own chart, spill onto neighbouring
/// charts, and inter-reflection that couples every chart within a few metres with the room's
/// mean albedo; entries below the noise cutoff dropped.
fn node_column(
    config: &SyntheticConfig,
    grid: Grid,
    node: usize,
    gain: LinearRgb,
    target_clean: &[LinearRgb],
) -> Result<AttenuationColumn, ModelError> {
    let (side, n) = (grid.side, grid.nodes);
    let rho = colorchecker::reflectances();
    let reach = 2.5;
    let (nx, ny) = grid.position(node);
    let mut dense: Vec<(usize, LinearRgb)> = Vec::new();
    let lo_x = (nx - reach).floor().max(0.0) as usize;
    let hi_x = ((nx + reach).ceil() as usize).min(side - 1);
    let lo_y = (ny - reach).floor().max(0.0) as usize;
    let hi_y = ((ny + reach).ceil() as usize).min(side - 1);
    for cy in lo_y..=hi_y {
        for cx in lo_x..=hi_x {
            let chart = cy * side + cx;
            if chart >= n {
                continue;
            }
            let d = ((cx as f64 - nx).powi(2) + (cy as f64 - ny).powi(2)).sqrt();
            let direct = if chart == node {
                0.85
            } else {
                0.25 * (-d * d / 0.5).exp()
            };
            let indirect = 0.08 * config.interreflection * (-d / 0.6).exp();
            for (j, r) in rho.iter().enumerate() {
                let p = r.hadamard(gain) * (direct + indirect);
                dense.push((chart * PATCHES_PER_CHART + j, p));
            }
        }
    }
    dense.sort_by_key(|&(i, _)| i);
    let mut support = Vec::with_capacity(dense.len());
    let mut values = Vec::with_capacity(dense.len());
    for (i, p) in dense {
        let sigma = noise_sigma(config.noise_floor, target_clean[i]);
        let kept = p.zip(
            sigma,
            |v, s| if v > config.cutoff_sigmas * s { v } else { 0.0 },
        );
        if kept.max_abs() > 0.0 {
            support.push(patch_id(i)?);
            values.push(kept);
        }
    }
    AttenuationColumn::new(support, values)
}

/// Shot-and-read noise of a patch mean: `σ = floor · (1 + 4·√signal)`.
fn noise_sigma(floor: f64, signal: LinearRgb) -> LinearRgb {
    signal.map(|v| floor * (1.0 + 4.0 * v.max(0.0).sqrt()))
}
