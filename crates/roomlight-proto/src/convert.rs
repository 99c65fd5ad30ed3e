//! Wire ↔ domain conversions, and the one mapping from protocol errors to gRPC statuses.
//!
//! Everything a peer sends is checked here before any domain type exists: lengths, sorted
//! patch ids, finite values, and for the batched per-round messages (one `Errors` and one
//! `Contribution` per node agent per round) the node ids, each at most once and owned by the
//! sender, and each node's errors as long as its support. It knows nothing of agents, rounds or streams: callers say which nodes a peer owns.

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
    /// Packed values are not whole triples.
    #[error(
        "{field}: {bytes} bytes of values, expected 24 per patch (three little-endian doubles)"
    )]
    RgbBytes { field: &'static str, bytes: usize },
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
    /// A value outside the range the protocol allows (a change of value beyond ±1).
    #[error("{field}: value {index} is {value:e}, expected {expected}")]
    OutOfRange {
        field: &'static str,
        index: usize,
        value: f64,
        expected: &'static str,
    },
    /// An enumeration's value this build does not know (or the unspecified one).
    #[error("{field}: {value} is not a known value")]
    UnknownValue { field: &'static str, value: i32 },
}

/// Largest sparse vector accepted (a node's support, or a room's patches).
pub const MAX_SPARSE_ENTRIES: usize = 1_000_000;

/// Most node entries one batched message may carry (a node agent drives one projector).
pub const MAX_BATCH_NODES: usize = 65_536;

/// Longest output name or reason a `DisplayStatus` may carry, in bytes: enough for any
/// output's name and an X error, too little to fill a camera agent's log.
pub const MAX_DISPLAY_TEXT: usize = 256;

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

/// A batched message's entries, read: the well-formed ones (node and what it carries), and
/// each refused one with why.
#[derive(Debug, Clone, PartialEq)]
pub struct Batch<T> {
    pub entries: Vec<(u32, T)>,
    /// Entries refused, each a [`ProtoError::Node`] naming the node and the reason.
    pub refused: Vec<ProtoError>,
}

/// One node's errors, packed: `values` on its support, in its column's order.
pub fn node_errors(
    node: u32,
    count: usize,
    values: impl IntoIterator<Item = LinearRgb>,
) -> v1::NodeErrors {
    v1::NodeErrors {
        node,
        values: pack_rgb(count, values),
    }
}

/// One node's change of value.
pub fn node_change(node: u32, change: LinearRgb) -> v1::NodeChange {
    v1::NodeChange {
        node,
        change: Some(to_rgb(change)),
    }
}

/// Reads a batch entry by entry: a node `check` refuses, or named a second time, is refused
/// with the reason and the others are kept. More than [`MAX_BATCH_NODES`] entries refuse the
/// message whole.
fn read_batch<E, T>(
    field: &'static str,
    entries: Vec<E>,
    node_of: impl Fn(&E) -> u32,
    mut check: impl FnMut(u32, E) -> Result<T, ProtoError>,
) -> Result<Batch<T>, ProtoError> {
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
    // Only accepted nodes enter `seen`: a scan costs at most the projector's node count.
    let mut seen: Vec<u32> = Vec::with_capacity(entries.len());
    for entry in entries {
        let node = node_of(&entry);
        let checked = if seen.contains(&node) {
            Err(ProtoError::Duplicate { field, node })
        } else {
            check(node, entry)
        };
        match checked {
            Ok(value) => {
                seen.push(node);
                batch.entries.push((node, value));
            }
            Err(reason) => batch.refused.push(ProtoError::Node {
                node,
                reason: Box::new(reason),
            }),
        }
    }
    Ok(batch)
}

/// Reads the entries of an `Errors` message: a node `owns` accepts, named once, with whole
/// triples of finite values (whether they match its support is the node's to judge).
pub fn from_node_errors(
    entries: Vec<v1::NodeErrors>,
    owns: impl Fn(u32) -> bool,
) -> Result<Batch<Vec<LinearRgb>>, ProtoError> {
    let field = "errors";
    read_batch(
        field,
        entries,
        |e| e.node,
        |node, e| {
            if !owns(node) {
                return Err(ProtoError::NotOwned { field, node });
            }
            if !e.values.len().is_multiple_of(RGB_BYTES) {
                return Err(ProtoError::RgbBytes {
                    field,
                    bytes: e.values.len(),
                });
            }
            unpack_rgb(field, &e.values)
        },
    )
}

/// Reads the entries of a `Contribution` message: a node `owns` accepts, named once, with a
/// finite change within ±1 per channel (a node's values lie in [0, 1], so no step moves one
/// further; 1e300 is not a change but an attack on the objective).
pub fn from_node_changes(
    entries: Vec<v1::NodeChange>,
    owns: impl Fn(u32) -> bool,
) -> Result<Batch<LinearRgb>, ProtoError> {
    let field = "contribution";
    read_batch(
        field,
        entries,
        |e| e.node,
        |node, e| {
            if !owns(node) {
                return Err(ProtoError::NotOwned { field, node });
            }
            let change = from_rgb(field, e.change.as_ref())?;
            match change.0.iter().position(|c| c.abs() > 1.0) {
                Some(index) => Err(ProtoError::OutOfRange {
                    field,
                    index,
                    value: change.0[index],
                    expected: "a change within [-1, 1]",
                }),
                None => Ok(change),
            }
        },
    )
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

/// A node's `DisplayStatus`, its strings cut to [`MAX_DISPLAY_TEXT`] bytes (at a character
/// boundary) so the camera agent never refuses it for its length.
pub fn display_status(state: v1::DisplayState, output: &str, reason: &str) -> v1::DisplayStatus {
    v1::DisplayStatus {
        state: state as i32,
        output: bounded(output).to_string(),
        reason: bounded(reason).to_string(),
    }
}

/// At most [`MAX_DISPLAY_TEXT`] bytes of `s`, cut at a character boundary.
fn bounded(s: &str) -> &str {
    let mut end = s.len().min(MAX_DISPLAY_TEXT);
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    &s[..end]
}

/// A `DisplayStatus` from the wire, checked: showing or lost (not unspecified, not a value of a
/// later version), its output and reason at most [`MAX_DISPLAY_TEXT`] bytes.
pub fn check_display_status(s: &v1::DisplayStatus) -> Result<v1::DisplayState, ProtoError> {
    for (field, text) in [
        ("display_status.output", &s.output),
        ("display_status.reason", &s.reason),
    ] {
        if text.len() > MAX_DISPLAY_TEXT {
            return Err(ProtoError::TooLarge {
                field,
                len: text.len(),
                max: MAX_DISPLAY_TEXT,
            });
        }
    }
    match v1::DisplayState::try_from(s.state) {
        Ok(state @ (v1::DisplayState::Showing | v1::DisplayState::Lost)) => Ok(state),
        _ => Err(ProtoError::UnknownValue {
            field: "display_status.state",
            value: s.state,
        }),
    }
}
