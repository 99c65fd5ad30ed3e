//! The forward model of DESIGN §2: `y_i = Σ_n p_{n,i} x_n + d_i`, per colour channel.
//!
//! Every constructor validates what it is given (finite, nonnegative where physics says so,
//! matching sizes) and says what was wrong; nothing here panics on bad input.

use crate::rgb::LinearRgb;
use serde::{Deserialize, Serialize};

/// Index of a chart patch in the room (chart `m`, patch `j` flattened by the caller).
pub type PatchId = u32;

/// What was wrong with model input. Each variant names the quantity and the offending place.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// A value is NaN or infinite.
    #[error("{what}: entry {index} channel {channel} is {value}, expected a finite number")]
    NotFinite {
        what: &'static str,
        index: usize,
        channel: usize,
        value: f64,
    },
    /// A value that physics says is nonnegative is negative.
    #[error("{what}: entry {index} channel {channel} is {value}, expected a value >= 0")]
    Negative {
        what: &'static str,
        index: usize,
        channel: usize,
        value: f64,
    },
    /// Two lists that must match in length do not.
    #[error("{what}: has {got} entries, expected {expected}")]
    Length {
        what: &'static str,
        got: usize,
        expected: usize,
    },
    /// Support patch ids are not strictly increasing.
    #[error("{what}: patch ids must be strictly increasing, got {previous} then {next}")]
    Unsorted {
        what: &'static str,
        previous: PatchId,
        next: PatchId,
    },
    /// A patch id beyond the room's patches.
    #[error("{what}: patch {patch} does not exist (the room has {patches} patches)")]
    PatchOutOfRange {
        what: &'static str,
        patch: PatchId,
        patches: usize,
    },
    /// A scalar parameter outside its allowed range.
    #[error("{what} = {value} is not allowed: expected {expected}")]
    Parameter {
        what: &'static str,
        value: f64,
        expected: &'static str,
    },
}

/// Checks that every channel of every entry is finite and, if `nonnegative`, at least zero.
pub(crate) fn validate_values(
    what: &'static str,
    values: &[LinearRgb],
    nonnegative: bool,
) -> Result<(), ModelError> {
    for (index, v) in values.iter().enumerate() {
        for channel in 0..3 {
            let value = v[channel];
            if !value.is_finite() {
                return Err(ModelError::NotFinite {
                    what,
                    index,
                    channel,
                    value,
                });
            }
            if nonnegative && value < 0.0 {
                return Err(ModelError::Negative {
                    what,
                    index,
                    channel,
                    value,
                });
            }
        }
    }
    Ok(())
}

pub(crate) fn check_len(what: &'static str, got: usize, expected: usize) -> Result<(), ModelError> {
    if got == expected {
        Ok(())
    } else {
        Err(ModelError::Length {
            what,
            got,
            expected,
        })
    }
}

/// One node's attenuation column `p_n` restricted to its support `S_n` (DESIGN §2): the
/// linear response of each supported patch to the node at full white, black offset removed.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct AttenuationColumn {
    support: Vec<PatchId>,
    values: Vec<LinearRgb>,
}

impl AttenuationColumn {
    /// Builds a column from strictly increasing patch ids and their finite, nonnegative responses.
    pub fn new(support: Vec<PatchId>, values: Vec<LinearRgb>) -> Result<Self, ModelError> {
        const WHAT: &str = "attenuation column";
        check_len(WHAT, values.len(), support.len())?;
        for w in support.windows(2) {
            if w[1] <= w[0] {
                return Err(ModelError::Unsorted {
                    what: WHAT,
                    previous: w[0],
                    next: w[1],
                });
            }
        }
        validate_values(WHAT, &values, true)?;
        Ok(Self { support, values })
    }

    /// Builds a column from a dense response over all patches, keeping only the entries that
    /// stand above `threshold_i` on some channel (DESIGN §2: "model only what the scene
    /// needs"). Channels at or below the threshold are set to zero.
    pub fn from_dense_with_cutoff(
        dense: &[LinearRgb],
        threshold: &[LinearRgb],
    ) -> Result<Self, ModelError> {
        check_len("cut-off thresholds", threshold.len(), dense.len())?;
        validate_values("dense attenuation", dense, true)?;
        validate_values("cut-off thresholds", threshold, true)?;
        let mut support = Vec::new();
        let mut values = Vec::new();
        for (i, (p, t)) in dense.iter().zip(threshold).enumerate() {
            let kept = p.zip(*t, |v, t| if v > t { v } else { 0.0 });
            if kept.max_abs() > 0.0 {
                support.push(patch_id(i)?);
                values.push(kept);
            }
        }
        Ok(Self { support, values })
    }

    /// The patches this node is modelled on, strictly increasing.
    pub fn support(&self) -> &[PatchId] {
        &self.support
    }

    /// `p_{n,i}` for each patch of the support, in support order.
    pub fn values(&self) -> &[LinearRgb] {
        &self.values
    }

    /// Number of patches in the support.
    pub fn len(&self) -> usize {
        self.support.len()
    }

    /// True for a node that no modelled patch sees.
    pub fn is_empty(&self) -> bool {
        self.support.is_empty()
    }

    /// `p_{n,i}` for one patch, zero off the support.
    pub fn get(&self, patch: PatchId) -> LinearRgb {
        self.support
            .binary_search(&patch)
            .map_or(LinearRgb::ZERO, |k| self.values[k])
    }

    /// Iterates `(patch, p_{n,i})` over the support.
    pub fn iter(&self) -> impl Iterator<Item = (PatchId, LinearRgb)> + '_ {
        self.support
            .iter()
            .copied()
            .zip(self.values.iter().copied())
    }
}

/// Converts a patch index to a [`PatchId`], failing past `u32::MAX` patches.
pub fn patch_id(i: usize) -> Result<PatchId, ModelError> {
    PatchId::try_from(i).map_err(|_| ModelError::PatchOutOfRange {
        what: "patch index",
        patch: PatchId::MAX,
        patches: i,
    })
}

/// The whole room's model, as a central party (camera agent, simulator, tests) sees it: every
/// node's column, black offsets `d`, targets `r` and per-patch noise `σ`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Problem {
    columns: Vec<AttenuationColumn>,
    black: Vec<LinearRgb>,
    target: Vec<LinearRgb>,
    noise: Vec<LinearRgb>,
}

impl Problem {
    /// Validates and builds a problem. `black`, `target` and `noise` have one entry per patch;
    /// all are finite and nonnegative, and every column's support lies inside the room.
    pub fn new(
        columns: Vec<AttenuationColumn>,
        black: Vec<LinearRgb>,
        target: Vec<LinearRgb>,
        noise: Vec<LinearRgb>,
    ) -> Result<Self, ModelError> {
        let patches = black.len();
        check_len("targets", target.len(), patches)?;
        check_len("noise", noise.len(), patches)?;
        validate_values("black offsets", &black, true)?;
        validate_values("targets", &target, true)?;
        validate_values("noise", &noise, true)?;
        for column in &columns {
            if let Some(&last) = column.support().last()
                && last as usize >= patches
            {
                return Err(ModelError::PatchOutOfRange {
                    what: "attenuation column",
                    patch: last,
                    patches,
                });
            }
        }
        Ok(Self {
            columns,
            black,
            target,
            noise,
        })
    }

    /// Runs every check of [`Problem::new`] and [`AttenuationColumn::new`] again: for a problem
    /// that came from outside (a file, the network) through serde, which does not validate.
    pub fn revalidate(self) -> Result<Self, ModelError> {
        let columns = self
            .columns
            .into_iter()
            .map(|c| AttenuationColumn::new(c.support, c.values))
            .collect::<Result<Vec<_>, _>>()?;
        Self::new(columns, self.black, self.target, self.noise)
    }

    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        self.columns.len()
    }

    /// Number of patches.
    pub fn patches(&self) -> usize {
        self.black.len()
    }

    /// All attenuation columns, one per node.
    pub fn columns(&self) -> &[AttenuationColumn] {
        &self.columns
    }

    /// Black offsets `d`.
    pub fn black(&self) -> &[LinearRgb] {
        &self.black
    }

    /// Targets `r`.
    pub fn target(&self) -> &[LinearRgb] {
        &self.target
    }

    /// Per-patch noise `σ` (standard error of the patch mean).
    pub fn noise(&self) -> &[LinearRgb] {
        &self.noise
    }

    /// A copy without the given nodes (a node that left the room).
    pub fn without_nodes(&self, gone: &[usize]) -> Self {
        let columns = self
            .columns
            .iter()
            .enumerate()
            .map(|(n, c)| {
                if gone.contains(&n) {
                    AttenuationColumn::default()
                } else {
                    c.clone()
                }
            })
            .collect();
        Self {
            columns,
            ..self.clone()
        }
    }

    /// A copy with another target.
    pub fn with_target(&self, target: Vec<LinearRgb>) -> Result<Self, ModelError> {
        Self::new(
            self.columns.clone(),
            self.black.clone(),
            target,
            self.noise.clone(),
        )
    }

    /// `s_i = Σ_n p_{n,i}`: every patch's response with all nodes at white (DESIGN §3.3).
    pub fn white_response(&self) -> Vec<LinearRgb> {
        let mut s = vec![LinearRgb::ZERO; self.patches()];
        for column in &self.columns {
            for (i, p) in column.iter() {
                s[i as usize] += p;
            }
        }
        s
    }

    /// `s` restricted to node `n`'s support, in support order: what the camera sends node `n`.
    pub fn white_response_on_support(&self, s: &[LinearRgb], n: usize) -> Vec<LinearRgb> {
        self.columns[n]
            .support()
            .iter()
            .map(|&i| s[i as usize])
            .collect()
    }

    /// The patch values `y = P x + d` for node values `x` (one per node).
    pub fn response(&self, x: &[LinearRgb]) -> Vec<LinearRgb> {
        let mut y = self.black.clone();
        for (column, &xn) in self.columns.iter().zip(x) {
            for (i, p) in column.iter() {
                y[i as usize] += p.hadamard(xn);
            }
        }
        y
    }

    /// The errors `e = r − (P x + d)`.
    pub fn errors(&self, x: &[LinearRgb]) -> Vec<LinearRgb> {
        let mut e = self.response(x);
        for (e, r) in e.iter_mut().zip(&self.target) {
            *e = *r - *e;
        }
        e
    }

    /// `G = ½ Σ_i ‖e_i‖²` summed over the three channels.
    pub fn objective(&self, x: &[LinearRgb]) -> f64 {
        crate::metrics::objective(&self.errors(x))
    }
}
