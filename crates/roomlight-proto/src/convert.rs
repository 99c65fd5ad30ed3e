//! Wire ↔ domain conversions, and the one mapping from protocol errors to gRPC statuses.
//!
//! Everything a peer sends is checked here before any domain type exists: lengths, sorted
//! patch ids, finite values, and for the batched per-round messages (one `Errors` and one
//! `Contribution` per node agent per round) the node ids, each at most once and owned by the
//! sender. It knows nothing of agents, rounds or streams: callers say which nodes a peer owns.

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
    #[error(
        "{field}: {bytes} bytes of values for {patches} patches, expected 24 per patch (three little-endian doubles)"
    )]
    Length {
        field: &'static str,
        bytes: usize,
        patches: usize,
    },
    /// A value is NaN or infinite.
    #[error("{field}: value {index} is {value}, expected a finite number")]
    NotFinite {
        field: &'static str,
        index: usize,
        value: f64,
    },
    /// Packed patch ids are not whole little-endian u32s.
    #[error("{field}: {bytes} bytes of patch ids, expected 4 per patch (little-endian u32)")]
    PatchBytes { field: &'static str, bytes: usize },
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
    /// An entry of a batched message names a node the sender does not own.
    #[error("{field}: node {node} is not one of this projector's nodes")]
    NotOwned { field: &'static str, node: u32 },
    /// An entry of a batched message names a node an earlier entry named.
    #[error("{field}: node {node} appears more than once")]
    Duplicate { field: &'static str, node: u32 },
    /// One node's entry of a batched message is malformed.
    #[error("node {node}: {reason}")]
    Node { node: u32, reason: Box<ProtoError> },
}

/// Largest sparse vector accepted (a node's support, or a room's patches).
pub const MAX_SPARSE_ENTRIES: usize = 1_000_000;

/// Most node entries one batched message may carry (a node agent drives one projector).
pub const MAX_BATCH_NODES: usize = 65_536;

impl From<ProtoError> for tonic::Status {
    fn from(e: ProtoError) -> Self {
        tonic::Status::invalid_argument(e.to_string())
    }
}

/// Bytes of one RGB triple on the wire: three little-endian doubles.
const RGB_BYTES: usize = 24;

/// Bytes of one patch id on the wire: a little-endian u32.
const PATCH_BYTES: usize = 4;

/// Packs patch ids and their values.
pub fn to_sparse(patches: &[PatchId], values: &[LinearRgb]) -> v1::SparseRgb {
    sparse_from_iter(patches, values.iter().copied())
}

/// Packs patch ids and their values, one value per patch in order, straight from an iterator
/// (a node's errors gathered from the room's, or its contribution computed as it goes).
pub fn sparse_from_iter(
    patches: &[PatchId],
    values: impl IntoIterator<Item = LinearRgb>,
) -> v1::SparseRgb {
    v1::SparseRgb {
        patches: pack_patches(patches),
        values: pack_rgb(patches.len(), values),
    }
}

/// Patch ids as little-endian u32s.
pub fn pack_patches(patches: &[PatchId]) -> Vec<u8> {
    let mut packed = Vec::with_capacity(PATCH_BYTES * patches.len());
    for p in patches {
        packed.extend_from_slice(&p.to_le_bytes());
    }
    packed
}

/// `values` as three little-endian doubles each (`count` of them expected, to size the buffer).
pub fn pack_rgb(count: usize, values: impl IntoIterator<Item = LinearRgb>) -> Vec<u8> {
    let mut packed = Vec::with_capacity(RGB_BYTES * count);
    for v in values {
        for c in v.0 {
            packed.extend_from_slice(&c.to_le_bytes());
        }
    }
    packed
}

/// Unpacks and validates: three finite values per patch, strictly increasing patch ids.
pub fn from_sparse(
    field: &'static str,
    sparse: &v1::SparseRgb,
) -> Result<(Vec<PatchId>, Vec<LinearRgb>), ProtoError> {
    let patches = unpack_patches(field, sparse)?;
    Ok((patches, unpack_rgb(field, &sparse.values)?))
}

/// [`from_sparse`], taking the message apart instead of copying its patch ids.
pub fn into_sparse(
    field: &'static str,
    sparse: v1::SparseRgb,
) -> Result<(Vec<PatchId>, Vec<LinearRgb>), ProtoError> {
    let patches = unpack_patches(field, &sparse)?;
    let values = unpack_rgb(field, &sparse.values)?;
    Ok((patches, values))
}

/// Packed triples back into values, every one finite (the length is checked by the caller).
fn unpack_rgb(field: &'static str, packed: &[u8]) -> Result<Vec<LinearRgb>, ProtoError> {
    let mut values = Vec::with_capacity(packed.len() / RGB_BYTES);
    for (k, triple) in packed.chunks_exact(RGB_BYTES).enumerate() {
        let mut v = [0.0; 3];
        for (c, bytes) in v.iter_mut().zip(triple.chunks_exact(8)) {
            let mut le = [0u8; 8];
            le.copy_from_slice(bytes);
            *c = f64::from_le_bytes(le);
        }
        if let Some(i) = v.iter().position(|c| !c.is_finite()) {
            return Err(ProtoError::NotFinite {
                field,
                index: 3 * k + i,
                value: v[i],
            });
        }
        values.push(LinearRgb(v));
    }
    Ok(values)
}

/// The patch ids: whole u32s, not too many, strictly increasing, with 24 bytes of values each.
fn unpack_patches(field: &'static str, sparse: &v1::SparseRgb) -> Result<Vec<PatchId>, ProtoError> {
    if !sparse.patches.len().is_multiple_of(PATCH_BYTES) {
        return Err(ProtoError::PatchBytes {
            field,
            bytes: sparse.patches.len(),
        });
    }
    let n = sparse.patches.len() / PATCH_BYTES;
    if n > MAX_SPARSE_ENTRIES {
        return Err(ProtoError::TooLarge {
            field,
            len: n,
            max: MAX_SPARSE_ENTRIES,
        });
    }
    if sparse.values.len() != RGB_BYTES * n {
        return Err(ProtoError::Length {
            field,
            bytes: sparse.values.len(),
            patches: n,
        });
    }
    let patches: Vec<PatchId> = sparse
        .patches
        .chunks_exact(PATCH_BYTES)
        .map(|b| PatchId::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    if let Some(w) = patches.windows(2).find(|w| w[1] <= w[0]) {
        return Err(ProtoError::Unsorted {
            field,
            previous: w[0],
            next: w[1],
        });
    }
    Ok(patches)
}

/// One node's entry of a batched message (its errors, or its contribution change), validated.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeVector {
    pub node: u32,
    pub patches: Vec<PatchId>,
    pub values: Vec<LinearRgb>,
}

/// One node's entry, packed: `values` in the order of `patches`, the node's support.
pub fn to_node_rgb(node: u32, patches: &[PatchId], values: &[LinearRgb]) -> v1::NodeRgb {
    v1::NodeRgb {
        node,
        values: Some(to_sparse(patches, values)),
    }
}

/// A batched message's entries, read: the well-formed ones, and each refused one with why.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Batch {
    pub entries: Vec<NodeVector>,
    /// Entries refused, each a [`ProtoError::Node`] naming the node and the reason.
    pub refused: Vec<ProtoError>,
}

/// Reads the entries of a batched `Errors` or `Contribution` message (`field` names which).
/// Each entry is checked on its own — a node `owns` accepts, named once, its values a valid
/// sparse vector — so that one malformed entry is refused with its reason while the others
/// count. A message of more than [`MAX_BATCH_NODES`] entries is refused whole.
pub fn from_node_rgbs(
    field: &'static str,
    entries: Vec<v1::NodeRgb>,
    mut owns: impl FnMut(u32) -> bool,
) -> Result<Batch, ProtoError> {
    if entries.len() > MAX_BATCH_NODES {
        return Err(ProtoError::TooLarge {
            field,
            len: entries.len(),
            max: MAX_BATCH_NODES,
        });
    }
    let mut batch = Batch {
        entries: Vec::with_capacity(entries.len()),
        refused: Vec::new(),
    };
    // Only owned nodes enter `seen`: a scan costs at most the projector's node count per entry.
    let mut seen: Vec<u32> = Vec::with_capacity(entries.len());
    for entry in entries {
        let node = entry.node;
        let checked = if seen.contains(&node) {
            Err(ProtoError::Duplicate { field, node })
        } else if !owns(node) {
            Err(ProtoError::NotOwned { field, node })
        } else {
            seen.push(node);
            entry
                .values
                .ok_or(ProtoError::Missing {
                    message: field,
                    field: "values",
                })
                .and_then(|sparse| into_sparse(field, sparse))
        };
        match checked {
            Ok((patches, values)) => batch.entries.push(NodeVector {
                node,
                patches,
                values,
            }),
            Err(reason) => batch.refused.push(ProtoError::Node {
                node,
                reason: Box::new(reason),
            }),
        }
    }
    Ok(batch)
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
