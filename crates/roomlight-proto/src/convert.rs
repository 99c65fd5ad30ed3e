//! Wire ↔ domain conversions, and the one mapping from protocol errors to gRPC statuses.

use crate::v1;
use roomlight_core::{LinearRgb, PatchId};

/// What is wrong with a message from a peer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProtoError {
    /// A required field is absent.
    #[error("{message}: field {field} is missing")]
    Missing {
        message: &'static str,
        field: &'static str,
    },
    /// Packed values do not match their patch ids.
    #[error("{field}: {values} values for {patches} patches, expected three per patch")]
    Length {
        field: &'static str,
        values: usize,
        patches: usize,
    },
    /// A value is NaN or infinite.
    #[error("{field}: value {index} is {value}, expected a finite number")]
    NotFinite {
        field: &'static str,
        index: usize,
        value: f64,
    },
    /// Patch ids are not strictly increasing.
    #[error("{field}: patch ids must be strictly increasing, got {previous} then {next}")]
    Unsorted {
        field: &'static str,
        previous: u32,
        next: u32,
    },
    /// More entries than the protocol allows.
    #[error("{field}: {len} entries, at most {max} allowed")]
    TooLarge {
        field: &'static str,
        len: usize,
        max: usize,
    },
}

/// Largest sparse vector accepted (a node's support, or a room's patches).
pub const MAX_SPARSE_ENTRIES: usize = 1_000_000;

impl From<ProtoError> for tonic::Status {
    fn from(e: ProtoError) -> Self {
        tonic::Status::invalid_argument(e.to_string())
    }
}

/// Packs patch ids and their values.
pub fn to_sparse(patches: &[PatchId], values: &[LinearRgb]) -> v1::SparseRgb {
    v1::SparseRgb {
        patches: patches.to_vec(),
        values: values.iter().flat_map(|v| v.0).collect(),
    }
}

/// Unpacks and validates: three finite values per patch, strictly increasing patch ids.
pub fn from_sparse(
    field: &'static str,
    sparse: &v1::SparseRgb,
) -> Result<(Vec<PatchId>, Vec<LinearRgb>), ProtoError> {
    let n = sparse.patches.len();
    if n > MAX_SPARSE_ENTRIES {
        return Err(ProtoError::TooLarge {
            field,
            len: n,
            max: MAX_SPARSE_ENTRIES,
        });
    }
    if sparse.values.len() != 3 * n {
        return Err(ProtoError::Length {
            field,
            values: sparse.values.len(),
            patches: n,
        });
    }
    if let Some((index, &value)) = sparse
        .values
        .iter()
        .enumerate()
        .find(|(_, v)| !v.is_finite())
    {
        return Err(ProtoError::NotFinite {
            field,
            index,
            value,
        });
    }
    if let Some(w) = sparse.patches.windows(2).find(|w| w[1] <= w[0]) {
        return Err(ProtoError::Unsorted {
            field,
            previous: w[0],
            next: w[1],
        });
    }
    let values = sparse
        .values
        .chunks_exact(3)
        .map(|c| LinearRgb([c[0], c[1], c[2]]))
        .collect();
    Ok((sparse.patches.clone(), values))
}

/// An RGB triple on the wire.
pub fn to_rgb(v: LinearRgb) -> v1::Rgb {
    v1::Rgb {
        r: v[0],
        g: v[1],
        b: v[2],
    }
}

/// An RGB triple from the wire, finite or refused.
pub fn from_rgb(field: &'static str, v: Option<&v1::Rgb>) -> Result<LinearRgb, ProtoError> {
    let v = v.ok_or(ProtoError::Missing {
        message: field,
        field: "rgb",
    })?;
    let out = LinearRgb([v.r, v.g, v.b]);
    if let Some((index, value)) = out
        .0
        .iter()
        .copied()
        .enumerate()
        .find(|(_, x)| !x.is_finite())
    {
        return Err(ProtoError::NotFinite {
            field,
            index,
            value,
        });
    }
    Ok(out)
}
