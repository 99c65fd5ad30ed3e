//! Wire conversions round-trip and refuse malformed input with a clear message.

use prost::Message;
use roomlight_core::LinearRgb;
use roomlight_proto::convert::{
    MAX_BATCH_NODES, NodeVector, ProtoError, from_node_rgbs, from_rgb, from_sparse, pack_patches,
    pack_rgb, to_node_rgb, to_rgb,
};
use roomlight_proto::v1;

#[test]
fn sparse_vectors_round_trip_through_bytes() {
    let patches = vec![2u32, 7, 40];
    let values = vec![
        LinearRgb([0.1, 0.2, 0.3]),
        LinearRgb([0.0, 1.0, 0.5]),
        LinearRgb([1e-9, 2.5, 0.25]),
    ];
    let msg = v1::Errors {
        round: 12,
        kind: v1::ErrorKind::Measured as i32,
        objective: 0.5,
        restart: true,
        nodes: vec![
            to_node_rgb(3, &patches, &values),
            to_node_rgb(4, &patches[..1], &values[..1]),
        ],
    };
    let bytes = msg.encode_to_vec();
    let back = v1::Errors::decode(bytes.as_slice()).expect("decodes");
    assert_eq!(back, msg);
    let sparse = back.nodes[0].values.as_ref().expect("errors");
    let (p, v) = from_sparse("errors", sparse).expect("valid");
    assert_eq!((p.clone(), v.clone()), (patches.clone(), values.clone()));
    let batch = from_node_rgbs("errors", back.nodes, |_| true).expect("a batch");
    assert!(batch.refused.is_empty(), "{:?}", batch.refused);
    assert_eq!(
        batch.entries,
        vec![
            NodeVector {
                node: 3,
                patches: p,
                values: v
            },
            NodeVector {
                node: 4,
                patches: vec![2],
                values: vec![values[0]]
            },
        ]
    );
    assert_eq!(
        from_rgb("x", Some(&to_rgb(LinearRgb([0.25, 0.5, 1.0])))).expect("rgb"),
        LinearRgb([0.25, 0.5, 1.0])
    );
}

#[test]
fn malformed_sparse_vectors_are_refused() {
    let short = v1::SparseRgb {
        patches: pack_patches(&[1, 2]),
        values: vec![0; 47],
    };
    assert!(matches!(
        from_sparse("delta", &short),
        Err(ProtoError::Length {
            bytes: 47,
            patches: 2,
            ..
        })
    ));
    let nan = v1::SparseRgb {
        patches: pack_patches(&[1]),
        values: pack_rgb(1, [LinearRgb([0.0, f64::NAN, 0.0])]),
    };
    let err = from_sparse("delta", &nan).expect_err("nan");
    assert!(
        err.to_string().contains("delta") && err.to_string().contains("finite"),
        "{err}"
    );
    let unsorted = v1::SparseRgb {
        patches: pack_patches(&[4, 4]),
        values: vec![0; 48],
    };
    assert!(matches!(
        from_sparse("delta", &unsorted),
        Err(ProtoError::Unsorted { .. })
    ));
    let ragged = v1::SparseRgb {
        patches: vec![1, 0, 0],
        values: Vec::new(),
    };
    let err = from_sparse("delta", &ragged).expect_err("three bytes");
    assert!(
        matches!(err, ProtoError::PatchBytes { bytes: 3, .. }),
        "{err}"
    );
    assert!(matches!(
        from_rgb("x", None),
        Err(ProtoError::Missing { .. })
    ));
    let status: tonic::Status = ProtoError::Length {
        field: "delta",
        bytes: 47,
        patches: 2,
    }
    .into();
    assert_eq!(status.code(), tonic::Code::InvalidArgument);
}

/// A batched contribution: each entry is checked on its own (owned by the sender, named once,
/// its values present, three finite values per increasing patch id); a malformed entry is
/// refused with a reason that names the node and what is wrong, and the others are kept.
#[test]
fn malformed_entries_of_a_batch_are_refused_one_by_one() {
    let good = |node: u32| to_node_rgb(node, &[1, 5], &[LinearRgb::splat(0.1); 2]);
    let nan = v1::NodeRgb {
        node: 12,
        values: Some(v1::SparseRgb {
            patches: pack_patches(&[1]),
            values: pack_rgb(1, [LinearRgb([0.0, f64::INFINITY, 0.0])]),
        }),
    };
    let short = v1::NodeRgb {
        node: 13,
        values: Some(v1::SparseRgb {
            patches: pack_patches(&[1, 2]),
            values: vec![0; 32],
        }),
    };
    let absent = v1::NodeRgb {
        node: 14,
        values: None,
    };
    let owned = |n: u32| (10..15).contains(&n);
    let batch = from_node_rgbs(
        "contribution",
        vec![good(10), good(99), good(10), nan, short, absent, good(11)],
        owned,
    )
    .expect("bounded");
    let kept: Vec<u32> = batch.entries.iter().map(|e| e.node).collect();
    assert_eq!(kept, [10, 11]);
    let reasons: Vec<String> = batch.refused.iter().map(ToString::to_string).collect();
    let expected = [
        "node 99: contribution: node 99 is not one of this projector's nodes",
        "node 10: contribution: node 10 appears more than once",
        "node 12: contribution: value 1 is inf, expected a finite number",
        "node 13: contribution: 32 bytes of values for 2 patches, expected 24 per patch (three little-endian doubles)",
        "node 14: contribution: field values is missing",
    ];
    assert_eq!(reasons, expected);
    // Too many entries: the whole message is refused before any is read.
    let flood = vec![v1::NodeRgb::default(); MAX_BATCH_NODES + 1];
    assert!(matches!(
        from_node_rgbs("contribution", flood, |_| true),
        Err(ProtoError::TooLarge { .. })
    ));
}
